"""Where the work runs and what is kept: local processes or a Dask cluster (``cluster``) and the
content-keyed cache (``cache``)."""
