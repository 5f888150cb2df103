"""The in-process runner and its configuration: the experiment parameters (``experiment_config``), the
network (``network_spec``), one cell (``scenario``), cells, keys, resumption and processes
(``sweep``), result files and tables (``files``, ``tables``), the machine (``machine``) and the
Dask cluster (``dask_cluster``)."""
