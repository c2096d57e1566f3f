"""The application: the ``shacc`` command line (``cli``, started by ``launch``) and one
module per command (``*_cmd``), each a thin layer over the library; ``inputs`` reads
the scene arguments, ``notebook_runner`` and ``reference`` are the Makefile's tools."""
