"""Type stubs of the extension module behind `gatetrace` (python/src/lib.rs). Lengths are metres
of optical path, radiance W m^-2 sr^-1."""

import os
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

class Scene:
    """A loaded glTF 2.0 or Mitsuba 3 XML scene, baked to world space with its BVH built."""

    @staticmethod
    def load(
        path: Union[str, os.PathLike],
        *,
        aperture_radius: Optional[float] = None,
        focus_distance: Optional[float] = None,
        allow_unsupported_materials: bool = False,
        parameters: Optional[Dict[str, str]] = None,
    ) -> "Scene":
        """Loads a .gltf, .glb or Mitsuba 3 XML file (`parameters`: values that replace the XML's
        `<default>`s, as ``render --define``); `aperture_radius` and `focus_distance` (m) make the camera a
        thin lens; `allow_unsupported_materials` renders materials using KHR_materials_transmission,
        KHR_materials_volume or KHR_materials_diffuse_transmission as opaque surfaces instead of
        refusing the scene. FileNotFoundError when the file does not exist, ValueError when it is
        unusable (a file in another format included)."""
    @property
    def path(self) -> "os.PathLike[str]":
        """The file the scene came from (a pathlib.Path)."""
    @property
    def triangles(self) -> int:
        """Number of triangles."""
    @property
    def settings(self) -> Dict[str, Any]:
        """Render settings the file carries (a Mitsuba scene's film, sampler and integrator), each
        None where absent: res (width, height), spp, max_bounces, gate (lengths in metres), seed."""
    @property
    def camera(self) -> Dict[str, Any]:
        """position, forward, up, right ([x, y, z], m and unit vectors), yfov (rad),
        aperture_radius and focus_distance (m, None for a pinhole)."""
    @property
    def lights(self) -> List[Dict[str, Any]]:
        """One dict per light: `type` point, spot, directional or area, and its parameters."""
    @property
    def nodes(self) -> List[str]:
        """Names of the named glTF nodes."""
    @property
    def bounds(self) -> Tuple[List[float], List[float]]:
        """Axis-aligned bounds (m): (min xyz, max xyz)."""
    def path_length_bounds(self, max_bounces: int) -> Tuple[float, float]:
        """Shortest and longest optical path length (m) of paths with at most `max_bounces`
        scattering vertices (bounds)."""

class Renderer:
    def __init__(
        self,
        scene: Scene,
        *,
        method: str = "path",
        max_bounces: int = 8,
        res: Tuple[int, int] = (256, 256),
        rr_depth: Optional[int] = None,
        samples_per_pass: Optional[int] = None,
        connections_per_query: Optional[int] = None,
        query_split: float = 1.0,
        query_bottom_nodes: int = 31,
        query_weights: str = "arcs",
        query_tree: str = "binary",
        medium_connections: bool = False,
    ) -> None: ...
    def render(
        self, gate: str, spp: Optional[int] = None, seconds: Optional[float] = None, seed: int = 0
    ) -> Tuple[npt.NDArray[np.float32], List[Tuple[str, str]]]:
        """(image [H, W, 3] or [H, W, T, 3], metadata as (key, value as JSON text) pairs)."""
    @property
    def settings(self) -> List[Tuple[str, str]]:
        """The settings every render shares: (key, value as JSON text) pairs."""

def capture(
    path: Union[str, os.PathLike],
    scan: Optional[str] = None,
    gate: Optional[str] = None,
    *,
    spp: Optional[int] = None,
    seconds: Optional[float] = None,
    seed: Optional[int] = None,
    method: Optional[str] = None,
    max_bounces: Optional[int] = None,
    res: Optional[Tuple[int, int]] = None,
    rr_depth: Optional[int] = None,
    samples_per_pass: Optional[int] = None,
    connections_per_query: Optional[int] = None,
    query_split: float = 1.0,
    query_bottom_nodes: int = 31,
    query_weights: Optional[str] = None,
    query_tree: str = "binary",
    target_pilot: Optional[int] = None,
    band_index: str = "auto",
    needle_guard: float = 1e-6,
    length_guard: float = 1e-5,
    relay_wall: Optional[str] = None,
    sensor_origin: Optional[Tuple[float, float, float]] = None,
    laser_origin: Optional[Tuple[float, float, float]] = None,
    laser_spot: Optional[Tuple[float, float]] = None,
    laser_grid: Optional[Tuple[int, int]] = None,
    laser_power: Optional[float] = None,
    count_first_last: bool = False,
    allow_unsupported_materials: bool = False,
    parameters: Optional[Dict[str, str]] = None,
) -> Tuple[npt.NDArray[np.float32], List[Tuple[str, str]]]:
    """An NLOS capture as `gatetrace render PATH --nlos SCAN` renders it (positions in m, laser
    power in W, seconds of rendering; None: a Mitsuba capture's own setting, else the command
    line's default): (data in the command line's .npy layout, metadata and the capture's record
    as (key, value as JSON text) pairs)."""

def describe_gate(spec: str) -> str:
    """What the renderer understands gate `spec` to be; ValueError when it is not a gate."""

def kernels_built() -> int:
    """Compute pipelines (kernels) built in this process so far."""

def device_name() -> str:
    """Adapter name, backend and type of the device renders run on."""

def version() -> str: ...
