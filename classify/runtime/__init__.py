"""Where the work runs and what is kept: local processes or a Dask cluster (``cluster``), the
content-keyed cache (``cache``), and points and imprints for a folder of meshes on a cluster
(``batch``)."""
