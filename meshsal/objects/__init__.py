"""Objects to recognize: the six procedural toys (``toys``: their shapes in ``toy_shapes``, built
from signed distance fields in ``sdf``, and their paint in ``toy_paint``), the ten embedded YCB scans
(``ycb``), objects by name (``names``) and fresh instances of any object, turned, resized and
repainted (``instances``)."""

from meshsal.objects.names import OBJECT_SETS, ObjectRef, distinct_files, load_object, load_ref, resolve_objects

__all__ = ["OBJECT_SETS", "ObjectRef", "resolve_objects", "distinct_files", "load_ref", "load_object"]
