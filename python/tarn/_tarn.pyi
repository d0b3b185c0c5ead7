"""Type stubs of tarn's Rust extension (``tarn._tarn``)."""

import os
from typing import Iterator, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, os.PathLike[str]]

class TarnError(Exception):
    """An error from tarn: bad input, a bad setting, a damaged file; tarn's message."""

class Map:
    """A hazard map: one record per observed cell, and the water bodies."""

    @property
    def resolution(self) -> float: ...
    @property
    def origin(self) -> tuple[float, float]:
        """Map-frame (x, y) of the lower-left corner of layer cell [0, 0]."""
    @property
    def shape(self) -> tuple[int, int]:
        """(rows along +y, columns along +x) of every layer."""
    @property
    def key_origin(self) -> tuple[int, int]: ...
    @property
    def bodies(self) -> list[dict[str, object]]:
        """Water bodies: report.json record of each, plus ``cells`` (N x 2 int64 keys)."""
    def __len__(self) -> int: ...
    @staticmethod
    def layer_names() -> list[str]:
        """elevation, sigma, water, class, hazard, depth, hits, below."""
    def layer(self, name: str) -> npt.NDArray[np.generic]:
        """A 2-D layer; unobserved cells NaN (float layers), 0 (class, hits, below), 255
        (hazard). ``hits`` and ``below`` are 0 in a map read from map.ply."""
    def keys(self) -> npt.NDArray[np.int64]: ...
    def at(self, x: float, y: float) -> Optional[dict[str, object]]:
        """The cell under map position (x, y): class, hazard, water, elevation, sigma,
        depth and body (its water body's id, or None); None where nothing was observed."""
    def write(self, dir: _Path) -> None:
        """map.ply, terrain.ply, water.ply and map.png into ``dir``."""
    def ply_bytes(self) -> bytes:
        """The bytes of the map's map.ply."""

class TileSet:
    """Per-tile cell statistics and water evidence; merges exactly."""

    def __init__(self, resolution: float = 0.1, z_ref: float = 0.0) -> None: ...
    def merge(self, other: TileSet) -> None:
        """Adds ``other``'s cells into this set, in place."""
    def to_bytes(self) -> bytes: ...
    @staticmethod
    def from_bytes(data: bytes) -> TileSet: ...
    @property
    def resolution(self) -> float: ...
    @property
    def z_ref(self) -> float: ...
    @property
    def tile_count(self) -> int: ...
    @property
    def points(self) -> int: ...
    @property
    def colour_false_alarms(self) -> tuple[int, int]:
        """``(samples, labelled water)``: the colour labels on the logs' dry ground."""
    def add_colour_false_alarms(self, samples: int, water: int) -> None: ...
    @property
    def swir_false_alarms(self) -> tuple[int, int]:
        """``(samples, labelled water)``: the SWIR labels on the logs' dry ground."""
    def add_swir_false_alarms(self, samples: int, water: int) -> None: ...
    def __len__(self) -> int: ...
    def tile_keys(self) -> list[tuple[int, int]]: ...
    def partition(self, parts: int) -> list[TileSet]: ...
    def blocks(
        self, side: int, origin: tuple[int, int] = (0, 0)
    ) -> list[tuple[tuple[int, int], TileSet]]:
        """``((bx, by), set)`` per block of side x side tiles from ``origin`` holding tiles."""
    def select_near(self, region: Sequence[tuple[int, int]], halo: int) -> TileSet:
        """The tiles within ``halo`` tiles (Chebyshev) of a tile of ``region``."""
    def copy(self) -> TileSet: ...

class Region:
    """The water stage of one region of a merged map (``finish_region``)."""

    @property
    def tiles(self) -> list[tuple[int, int]]:
        """Decided tiles holding observed cells."""
    @property
    def undecided(self) -> list[tuple[int, int]]:
        """Tiles to finish again with a larger halo."""
    @property
    def tiles_read(self) -> int: ...
    def __len__(self) -> int: ...
    def to_bytes(self) -> bytes: ...
    @staticmethod
    def from_bytes(data: bytes) -> Region: ...

class Frame:
    @property
    def stamp(self) -> float: ...
    @property
    def position(self) -> tuple[float, float, float]: ...
    def lidar_points(self) -> Optional[npt.NDArray[np.float64]]: ...

class FrameIter(Iterator[Frame]):
    def __iter__(self) -> FrameIter: ...
    def __next__(self) -> Frame: ...
    @property
    def errors(self) -> list[str]: ...

class Mapper:
    def __init__(self, config: Optional[_Path] = None, publish: bool = False) -> None: ...
    def update(self, frame: Frame) -> dict[str, object]: ...
    def calibrate(self, frame: Frame) -> None:
        """Measures the sensors' noise on a frame without mapping it, as an offline build
        does on the log's first frames before it maps any."""
        ...
    @property
    def calibration_settled(self) -> bool: ...
    def hold_calibration(self) -> None: ...
    def calibration(self) -> str:
        """Every sensor value used so far, its source and what the log measured (JSON)."""
        ...
    @property
    def frames(self) -> int: ...
    def hazard_map(self) -> Map: ...
    def take_left_tiles(self) -> TileSet:
        """The cells that have left the window so far, which the mapper then forgets; merged
        with every other take and ``finish_tiles()`` they are ``finish_tiles()`` alone."""
        ...
    def finish(self) -> Map: ...
    def finish_tiles(self) -> TileSet: ...

def build(path: _Path, config: Optional[_Path] = None) -> Map: ...
def build_many(paths: Sequence[_Path], config: Optional[_Path] = None) -> Map: ...
def build_tiles(
    path: _Path,
    config: Optional[_Path] = None,
    start: Optional[float] = None,
    end: Optional[float] = None,
) -> TileSet: ...
def finish(tiles: TileSet, config: Optional[_Path] = None) -> Map: ...
def finish_region(
    tiles: TileSet,
    region: Sequence[tuple[int, int]],
    halo: int,
    bounds: tuple[tuple[int, int], tuple[int, int]],
    config: Optional[_Path] = None,
) -> Region: ...
def join_regions(regions: Sequence[Region]) -> Map: ...
def read_map(dir: _Path) -> Map: ...
def read_frames(path: _Path, config: Optional[_Path] = None) -> FrameIter: ...
