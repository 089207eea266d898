"""splatray: ray tracing point clouds as surface splats, numpy in and out.

* :func:`read_points` reads a point file into a :class:`PointCloud`;
* :func:`splat` turns points (a cloud or arrays) into :class:`Splats`, as
  ``splatray splat`` does, with the command's option names;
* :class:`SplatScene` casts rays against splats (``cast_rays``,
  ``count_intersections``, ``occluded``), resolved as the renderer
  resolves its camera rays, with either backend of :data:`BACKENDS`, and
  against triangles beside them (``vertices``/``faces`` arrays, or a
  scene's ``triangles`` models through ``Scene.splat_scene``): hit ids
  from ``first_triangle`` on are faces;
* :class:`Scene` (from TOML, or built here from ``Splats`` and
  ``PointCloud`` models) renders an :class:`Image` (linear float32 RGB
  and AOVs; shown as an image in a notebook);
* :func:`scan_check` and :func:`sweep` return the reports of
  ``splatray scan-check`` and ``splatray sweep`` as dicts.

The work runs with the GIL released; ``progress`` callbacks get
``(stage, fraction)``; the library's errors are raised as
:class:`SplatrayError` with its one-line messages, bad arrays as
``TypeError``/``ValueError`` before any work.
"""

from ._splatray import (
    BACKENDS,
    INVALID_ID,
    Image,
    PointCloud,
    Scene,
    SplatrayError,
    SplatScene,
    Splats,
    read_image,
    read_points,
    scan_check,
    splat,
    sweep,
)

__all__ = [
    "BACKENDS",
    "INVALID_ID",
    "Image",
    "PointCloud",
    "Scene",
    "SplatrayError",
    "SplatScene",
    "Splats",
    "read_image",
    "read_points",
    "scan_check",
    "splat",
    "sweep",
]
