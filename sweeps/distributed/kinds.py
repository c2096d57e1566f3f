"""The names a sweep's processes agree on: the two kinds of worker, as the Dask
resources their tasks ask for, and the name of the plugin every shacc worker runs.
Nothing else, so that every module of the runner can import it."""

PRECOMPUTE = "precompute"  # a CPU worker: precompute, bake, tables
EVALUATE = "evaluate"      # the worker that holds an accelerator (or the CPU's)
PLUGIN = "shacc-setup"     # sweeps.distributed.worker_setup.WorkerSetup's name
