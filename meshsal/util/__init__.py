"""The toolkit's infrastructure, used by every package: atomic writes (``atomic``), progress bars
(``progress``), registries of choices (``registry``), JSON and NumPy-archive reading within caps
(``jsonfile``, ``npzfile``), the same numeric kernels on every CPU (``reproducible``), errors that name
the object being processed (``errors``), pymeshlab imported by a thread that lasts (``meshlab``) and
measurement pages that say where and when they were measured (``pages``).  Nothing here knows about
meshes."""
