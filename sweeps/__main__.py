"""``python -m sweeps ...`` is the ``shacc`` console script (``sweeps.app.launch``)."""

from sweeps.app.launch import entry

entry()
