"""The 72 views of a mesh: cameras, the rig and their framing (``cameras``), the CPU renderer
(``render``), its robust first hits through Embree's fast traversal (``tracer``), the paper's
analytic pixel projection (``paper_projection``), and pictures of views, maps and points
(``overlay``)."""
