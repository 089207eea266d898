"""Type stubs of splatray's native module (python/splatray-py/src)."""

from os import PathLike
from typing import Callable, Optional, Sequence, TypedDict, Union

from typing_extensions import Required

import numpy as np
import numpy.typing as npt

Path = Union[str, PathLike[str]]
Progress = Callable[[str, float], object]
ArrayF = npt.NDArray[np.floating]

BACKENDS: list[str]
"""Every backend name; the first is the default."""
INVALID_ID: int
"""The splat id of a miss (2**32 - 1)."""

class SplatrayError(RuntimeError):
    """An error of the splatray library, with its one-line message."""

class PointCloud:
    """Points in the file's coordinates (float64), with optional normals,
    colours (linear RGB in [0, 1]), viewpoint and organised grid."""
    def __init__(
        self,
        positions: ArrayF,
        normals: Optional[ArrayF] = None,
        colors: Optional[ArrayF] = None,
        viewpoint: Optional[Sequence[float]] = None,
    ) -> None: ...
    def __len__(self) -> int: ...
    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """(N, 3) float64."""
    @property
    def origin(self) -> tuple[float, float, float]: ...
    @property
    def normals(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def colors(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def viewpoint(self) -> Optional[tuple[float, float, float]]: ...
    @property
    def grid(self) -> Optional[tuple[int, int]]:
        """(rows, columns) of an organised scan."""
    @property
    def skipped(self) -> list[tuple[str, int]]: ...

def read_points(path: Path) -> PointCloud:
    """Reads .ply, .pcd, .xyz/.txt, .las/.laz or .e57 (or known by its first bytes)."""

class Splats:
    """Oriented splats with linear (Phong) normal fields, eq. (4); centres
    are float32 offsets from a float64 origin, as the splat PLY holds them."""
    @staticmethod
    def load(path: Path) -> Splats: ...
    def save(self, path: Path) -> None:
        """The splat PLY `splatray splat` writes, atomically."""
    def __len__(self) -> int: ...
    @property
    def centers(self) -> npt.NDArray[np.float64]:
        """(N, 3) float64, in the cloud's coordinates."""
    @property
    def origin(self) -> tuple[float, float, float]: ...
    @property
    def normals(self) -> npt.NDArray[np.float32]: ...
    @property
    def u_axes(self) -> npt.NDArray[np.float32]: ...
    @property
    def v_axes(self) -> npt.NDArray[np.float32]: ...
    @property
    def radii(self) -> npt.NDArray[np.float32]:
        """(N, 2) radii along u and v."""
    @property
    def normal_fields(self) -> npt.NDArray[np.float32]:
        """(N, 4): x_c, y_c, alpha, beta of eq. (4)."""
    @property
    def clip_lines(self) -> npt.NDArray[np.float32]:
        """(N, 6): two clip lines (a, b, d) per splat; the splat keeps
        a*u + b*v <= d (u, v in units of its radii); zeros keep all."""
    @property
    def colors(self) -> npt.NDArray[np.float32]: ...
    @property
    def color_fields(self) -> Optional[npt.NDArray[np.float32]]:
        """(N, 6): du, dv, or None."""
    @property
    def report(self) -> Optional[dict]:
        """`splat`'s generation and trimming report."""

def splat(
    points: Union[PointCloud, ArrayF],
    normals: Optional[ArrayF] = None,
    colors: Optional[ArrayF] = None,
    viewpoint: Optional[Sequence[float]] = None,
    *,
    epsilon: Optional[float] = None,
    k: Optional[int] = None,
    density: Optional[float] = None,
    ellipses: bool = False,
    flat_colors: bool = False,
    creases: Optional[bool] = None,
    no_viewpoint: bool = False,
    thin: Optional[float] = None,
    lean: bool = True,
    progress: Optional[Progress] = None,
) -> Splats:
    """Splats from points as `splatray splat` makes them; the options are
    its flags (epsilon: fraction of the bounding-box diagonal; creases=True
    is --creases: splats clipped at creases, corners and borders everywhere,
    False --no-creases: whole discs, None the default: clipped but in a cloud
    sampled along scan lines; lean=False is --no-lean: the stages on any
    cloud; by default lean growth where its gate finds the cloud clean,
    dense and closed, the report's "lean" saying what it found)."""

class CastResult(TypedDict, total=False):
    t_hit: Required[npt.NDArray[np.float32]]
    splat_ids: npt.NDArray[np.uint32]
    normals: npt.NDArray[np.float32]

class SplatScene:
    """Splats, and triangles beside them, in one backend, for ray casting
    (cf. Open3D's RaycastingScene)."""
    def __init__(
        self,
        splats: Splats,
        backend: Optional[str] = None,
        *,
        vertices: Optional[ArrayF] = None,
        faces: Optional[npt.NDArray[np.integer]] = None,
    ) -> None:
        """With `vertices` (V, 3) float and `faces` (F, 3) int32/int64/uint32/
        uint64 indices, those triangles too, in the splats' coordinates: face
        i is hit id `first_triangle + i`. A NaN vertex, an index out of
        range or negative, or a degenerate face raises ValueError naming
        the row; a wrong shape or dtype, ValueError or TypeError."""
    @property
    def backend(self) -> str: ...
    @property
    def first_triangle(self) -> int:
        """The splats' count: ids below it are splats, from it on triangles."""
    @property
    def triangles(self) -> int: ...
    def cast_rays(self, rays: ArrayF, splat_ids: bool = True, normals: bool = True) -> CastResult:
        """rays (N, 6) float32/float64: origin, direction (any length), in
        the splats' coordinates. t_hit in units of the direction's length
        (inf: miss), splat_ids (INVALID_ID: miss; a triangle from
        first_triangle on), resolved shading normals; the last two only
        when asked for (both are by default)."""
    def count_intersections(self, rays: ArrayF, limit: int = 1024) -> npt.NDArray[np.int32]: ...
    def occluded(self, rays: ArrayF, tnear: float = 0.0, tfar: float = ...) -> npt.NDArray[np.bool_]: ...
    def compute_closest_points(self, query_points: ArrayF) -> dict[str, np.ndarray]:
        """query_points (N, 3) float32/float64, the splats' coordinates:
        points (N, 3) float64 on the nearest surface (a splat's disc within
        its clip lines, or a triangle), splat_ids (N,) uint32 (the lowest on
        equal distances), normals (N, 3) float32 (its geometric normal)."""
    def compute_distance(self, query_points: ArrayF) -> npt.NDArray[np.float32]: ...
    def compute_signed_distance(self, query_points: ArrayF) -> npt.NDArray[np.float32]:
        """compute_distance, negative behind the nearest surface's normal."""

class Image:
    """A render: linear RGB and AOVs; `_repr_png_` shows it in a notebook."""
    @property
    def rgb(self) -> npt.NDArray[np.float32]:
        """(H, W, 3) linear radiance."""
    @property
    def aov(self) -> dict[str, np.ndarray]:
        """depth (H, W) float32, normal/albedo (H, W, 3) float32, splat (H, W) uint32."""
    @property
    def shape(self) -> tuple[int, int]: ...
    @property
    def report(self) -> dict: ...
    def save(self, path: Path) -> None:
        """.png (8-bit sRGB) or .exr (linear), as `splatray render` writes."""
    def save_aov(self, name: str, path: Path) -> None: ...
    def _repr_png_(self) -> bytes: ...

class Scene:
    """A scene: camera, lights, materials, models (a scene file's tables)."""
    def __init__(
        self,
        camera: dict,
        models: list[dict],
        lights: Optional[list[dict]] = None,
        render: Optional[dict] = None,
        background: Optional[Sequence[float]] = None,
    ) -> None: ...
    @staticmethod
    def from_toml(path: Path) -> Scene: ...
    def render(
        self,
        backend: Optional[str] = None,
        width: Optional[int] = None,
        height: Optional[int] = None,
        spp: Optional[int] = None,
        shading: Optional[str] = None,
        aov: Optional[Sequence[str]] = None,
        progress: Optional[Progress] = None,
    ) -> Image: ...
    def compare(
        self,
        rounds: int = 1,
        truth: bool = False,
        width: Optional[int] = None,
        height: Optional[int] = None,
        spp: Optional[int] = None,
        progress: Optional[Progress] = None,
    ) -> dict:
        """`splatray compare`'s report: every renderer backend's speed,
        memory and agreement with the first; with truth, the errors."""
    def camera_rays(self, width: Optional[int] = None, height: Optional[int] = None) -> npt.NDArray[np.float64]:
        """(H*W, 6) rays through the pixel centres, for splat_scene().cast_rays."""
    def splat_scene(self, backend: Optional[str] = None) -> SplatScene: ...

def read_image(path: Path) -> npt.NDArray[np.float32]:
    """(H, W, 3) float32 of an EXR (linear) or PNG (scaled to [0, 1])."""

def scan_check(
    path: Path,
    *,
    tolerance: float = 0.01,
    holdout: float = 0.1,
    seed: int = 1,
    photo: bool = False,
    backend: Optional[str] = None,
    epsilon: Optional[float] = None,
    k: Optional[int] = None,
    density: Optional[float] = None,
    ellipses: bool = False,
    flat_colors: bool = False,
    creases: Optional[bool] = None,
    viewpoint: Optional[Sequence[float]] = None,
    no_viewpoint: bool = False,
    thin: Optional[float] = None,
    progress: Optional[Progress] = None,
) -> dict:
    """`splatray scan-check`'s JSON report as a dict: `holdout` of the
    points held out, splats grown from the rest (the options are `splat`'s)
    and a line of sight cast from the scanner to each held-out point, a hit
    within `tolerance` of its distance consistent; with `photo`, the photo
    check of an organised colour capture, rendered with `backend`."""

def sweep(
    scene: Path,
    *,
    width: int = 320,
    height: int = 240,
    steps: int = 6,
    eps_coarse: float = 0.05,
    eps_fine: float = 0.0005,
    progress: Optional[Progress] = None,
) -> list[dict]:
    """`splatray sweep` as one dict per (budget step, shading mode), the
    rows its CSV holds: splat counts, each backend's build and render
    seconds, rays per second, memory and errors against the exact surface
    (report §4.4, fig. 16), and whether the backends agree bit for bit;
    then the mesh row (`shading` "mesh"): the meshes as `triangles`
    shaded smooth as the exact surface is, on each backend, with its
    speed and its measured errors against the exact surface. `steps`
    (5 to 64) epsilons from `eps_coarse` to `eps_fine`, fractions of the
    bounding-box diagonal; bad options raise ValueError before any work."""

def main(argv: list[str]) -> int:
    """Runs the `splatray` command line (the binary's, compiled into this
    module) with `argv`, the program's name first, and returns its exit
    status (0; 1 after its one-line error; 2 after a usage error; 101 after
    a panic). Output goes to the process's stdout and stderr. The
    `splatray` command and `python -m splatray` call it
    (`splatray.__main__.main`)."""
