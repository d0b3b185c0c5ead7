"""tarn for Python: 2.5-D terrain and water-hazard maps from robot logs.

The functions and classes are tarn's Rust library (``tarn._tarn``); numpy arrays in and out.

- ``build(path)``, ``build_many(paths)``: the map of one log, or of many (each log built on
  its own, merged exactly, the water stage run once over the whole).
- ``build_tiles(path)`` -> ``TileSet``; ``TileSet.merge``, ``to_bytes``/``from_bytes``;
  ``finish(tiles)`` -> ``Map``: the same as a map-reduce, for any split of logs and any
  order of merging.
- ``read_frames(path)`` and ``Mapper(config).update(frame)``: the online mapper.
- ``read_map(dir)``: a map that ``tarn build`` wrote.
- ``finish_region(tiles, region, halo, bounds)`` -> ``Region``; ``join_regions(regions)``:
  the water stage region by region, each read with a halo of tiles; joined, ``finish`` of
  the whole, byte for byte (tiles a region cannot decide are finished again, larger halo).
- ``tarn.dask.build_many(logs, client)``: logs built on a Dask cluster.

Errors are ``TarnError`` (``OSError`` for files that cannot be opened) with tarn's message.
"""

from ._tarn import (
    Frame,
    FrameIter,
    Map,
    Mapper,
    Region,
    TarnError,
    TileSet,
    __version__,
    build,
    build_many,
    build_tiles,
    finish,
    finish_region,
    join_regions,
    read_frames,
    read_map,
)

__all__ = [
    "Frame",
    "FrameIter",
    "Map",
    "Mapper",
    "Region",
    "TarnError",
    "TileSet",
    "__version__",
    "build",
    "build_many",
    "build_tiles",
    "finish",
    "finish_region",
    "join_regions",
    "merge",
    "read_frames",
    "read_map",
]


def merge(tilesets):
    """A new ``TileSet``: every set of ``tilesets`` merged (none of them is changed)."""
    it = iter(tilesets)
    try:
        out = next(it).copy()
    except StopIteration:
        raise ValueError("merge of no tile sets") from None
    for t in it:
        out.merge(t)
    return out
