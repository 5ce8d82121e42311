"""The 72 views of a mesh: the CPU renderer (``render``), its robust first hits through Embree's
fast traversal (``tracer``), and pictures of views, maps and points (``overlay``)."""
