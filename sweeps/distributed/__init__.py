"""The distributed runner: a sweep on Dask. ``runner`` drives it (chunks from ``plan``,
the driver alone writes), ``cluster`` starts the local cluster or joins one,
``worker_setup`` is every worker's plugin, ``evaluation_worker`` what the chunk tasks
run; ``faults`` and ``interrupt`` turn every fault and Ctrl-C into one line and end
every process the command started."""
