"""The toolkit's infrastructure, used by every package: atomic writes (``atomic``), progress bars
(``progress``), registries of choices (``registry``), JSON reading with clear errors (``jsonfile``),
lazy package attributes (``lazy``), the same numeric kernels on every CPU (``reproducible``) and
errors that name the object being processed (``errors``) and measurement pages that say where and when they were measured (``pages``).  Nothing here knows about meshes."""
