"""Runs splatray's tiled splat generation and its renders on a Dask cluster.

The binary does the work; this package plans, submits and merges:

* ``splat``: ``splatray splat IN... -o OUT --plan-only`` once (survey, plan,
  spill into ``.OUT.tiles`` beside the output), then one task per tile
  (``--tile T``), then ``--merge-only``. Every task writes its result
  atomically into the shared work folder and a tile found finished is
  skipped, so a task Dask retries (its worker died) gives the same bytes.
* ``render``: one task per horizontal band of the image (``--band I/N``,
  by default one band per worker, so each worker loads the splats once),
  then ``splatray stitch`` joins the bands into the image.

Workers must see the same paths (a shared filesystem), run the same
splatray binary, and have this package installed (it ships in the
``splatray`` wheel: the scheduler and the workers unpickle its tasks). The output is byte-identical to a one-machine run.
"""

from .driver import RENDER_OPTIONS, SPLAT_OPTIONS, SplatrayError, render, run_binary, splat

__all__ = ["RENDER_OPTIONS", "SPLAT_OPTIONS", "SplatrayError", "render", "run_binary", "splat"]
