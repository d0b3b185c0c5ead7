"""Offline builds of many logs on a Dask cluster.

``build_many(logs, client)``:

1. one task per log builds its ``TileSet`` (``tarn.build_tiles``; the Rust code releases
   the interpreter, so threaded workers build in parallel); the client gathers only the
   tile keys, for the map's bounds;
2. the map's tiles are cut into regions of ``region_tiles`` x ``region_tiles`` tiles from
   the corner of its bounds (``TileSet.blocks``); each region is tree-reduced on the workers: pairwise merges of
   the logs' parts, ``log(n)`` levels deep;
3. each region's water stage runs on a worker (``tarn.finish_region``) over the region and
   a halo of ``halo`` tiles around it, cut from the merged neighbouring regions
   (``TileSet.select_near``). A region decides every tile whose cells' classes, hazards
   and water bodies do not depend on anything beyond its halo; a water body (or the ring
   of cells its surface fit reads) that reaches the halo's edge leaves the tiles it
   touches undecided, and those are finished again, as a region of their own, with twice
   the halo, until none is left;
4. the client gathers the finished regions and joins them (``tarn.join_regions``).

Merging is exact (integer sums) and a decided tile's records are those of the whole map's
water stage, so the map is byte-identical to ``tarn.build_many`` in one process, for any
number of workers, any region size and halo, and any order the tasks run in. A worker
holds two logs' parts of one region (a merge) or one region and its halo (a finish),
except where a body is larger than the halo: the halo then grows until it holds the body.
Logs are the unit of work: time chunks of one log would not merge to its one-pass map (a
frame's cues read the window the earlier frames left), so a log is never split.

Command line: ``python -m tarn.dask LOG... --out DIR [--scheduler ADDRESS]`` (a
``LocalCluster`` by default).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import Any, Optional, Sequence

import tarn

__all__ = ["build_many", "main"]


def _tiles_of_log(path: str, config: Optional[str]):
    return tarn.build_tiles(path, config)


def _keys(t) -> list:
    return t.tile_keys()


def _blocks(t, side: int, origin) -> dict:
    return dict(t.blocks(side, origin))


def _pick(blocks: dict, b):
    return blocks[b]


def _merge2(a, b):
    # A new set: with threaded workers a task's inputs are shared objects.
    out = a.copy()
    out.merge(b)
    return out


def _near(t, region: list, halo: int):
    return t.select_near(region, halo)


def _alarms(t) -> tuple:
    return t.colour_false_alarms, t.swir_false_alarms


def _finish(crops: list, region: list, halo: int, bounds, config: Optional[str], alarms):
    # The crops hold cells only: the region is finished under the whole build's rates.
    m = tarn.merge(crops)
    colour, swir = alarms
    m.add_colour_false_alarms(*colour)
    m.add_swir_false_alarms(*swir)
    return tarn.finish_region(m, region, halo, bounds, config)


def _nbytes(t) -> int:
    return len(t.to_bytes())


def _points(t) -> int:
    return t.points


def _side(bounds, parts: int) -> int:
    """A region side (tiles) cutting the bounds into at most ceil(sqrt(parts)) squares a side."""
    (x0, y0), (x1, y1) = bounds
    across = max(x1 - x0, y1 - y0) + 1
    return max(1, math.ceil(across / math.ceil(math.sqrt(max(1, parts)))))


def build_many(
    logs: Sequence[str | os.PathLike],
    client: Any,
    config: Optional[str | os.PathLike] = None,
    parts: Optional[int] = None,
    stats: Optional[dict] = None,
    region_tiles: Optional[int] = None,
    halo: int = 2,
) -> "tarn.Map":
    """The map of ``logs`` built on the Dask ``client``'s cluster (see the module doc).

    ``config``: a ``tarn.toml`` path readable by the workers (``None``: what ``tarn build``
    uses). ``region_tiles``: the side of a region, tiles (64 cells); by default the map's
    bounds are cut into at most ``ceil(sqrt(parts))`` squares a side (``parts`` defaults
    to the cluster's worker threads, at least 1). ``halo``: tiles read around a region (at
    least 1). ``stats``: a dict to fill with what travelled: ``log_bytes`` (the logs' parts of each region, as
    tile-set bytes), ``merge_bytes`` (the merged sets each merge produced), ``halo_bytes``
    (the cuts of merged regions each finish read), ``result_bytes`` (the finished regions
    the client gathered), ``points`` (points in the logs' cells), ``parts`` (regions),
    ``refinished_tiles`` (tiles finished again with a larger halo), ``largest_halo``,
    ``most_tiles_read`` (the most tiles one finish read), and ``seconds`` (wall time from
    the first task to the joined map: builds, merges and finishes overlap).
    """
    paths = [os.fspath(p) for p in logs]
    if not paths:
        raise ValueError("no logs to build")
    if halo < 1:
        raise ValueError(f"a halo of {halo} tiles: a region reads at least 1 tile around it")
    if region_tiles is not None and region_tiles < 1:
        raise ValueError(f"regions of {region_tiles} tiles: the side is at least 1")
    cfg = None if config is None else os.fspath(config)
    if parts is None:
        nthreads = client.nthreads() if hasattr(client, "nthreads") else {}
        parts = max(1, sum(nthreads.values()))
    t0 = time.perf_counter()
    per_log = [
        client.submit(_tiles_of_log, p, cfg, key=f"tarn-tiles-{i}", pure=False)
        for i, p in enumerate(paths)
    ]
    keys = [
        [tuple(k) for k in ks]
        for ks in client.gather([client.submit(_keys, f, pure=False) for f in per_log])
    ]
    per_log_alarms = client.gather([client.submit(_alarms, f, pure=False) for f in per_log])
    # Per camera (colour, SWIR): (samples, labelled water), summed over the logs.
    alarms = tuple(
        tuple(sum(a[cam][i] for a in per_log_alarms) for i in range(2)) for cam in range(2)
    )
    every = sorted(set().union(*map(set, keys)))
    if not every:
        # Nothing observed: the empty map, with the logs' resolution.
        return tarn.finish(tarn.merge(client.gather(per_log)), cfg)
    bounds = (
        (min(k[0] for k in every), min(k[1] for k in every)),
        (max(k[0] for k in every), max(k[1] for k in every)),
    )
    extent = max(bounds[1][0] - bounds[0][0], bounds[1][1] - bounds[0][1])
    side = region_tiles if region_tiles is not None else _side(bounds, parts)

    ox, oy = bounds[0]

    def block(k):
        return ((k[0] - ox) // side, (k[1] - oy) // side)

    per_log_blocks = [client.submit(_blocks, f, side, bounds[0], pure=False) for f in per_log]
    holders: dict = {}
    for i, ks in enumerate(keys):
        for b in {block(k) for k in ks}:
            holders.setdefault(b, []).append(i)
    picks = []
    merges = []
    merged = {}
    for b in sorted(holders):
        level = [client.submit(_pick, per_log_blocks[i], b, pure=False) for i in holders[b]]
        picks.extend(level)
        while len(level) > 1:
            nxt = [
                client.submit(_merge2, level[k], level[k + 1], pure=False)
                for k in range(0, len(level) - 1, 2)
            ]
            merges.extend(nxt)
            if len(level) % 2:
                nxt.append(level[-1])
            level = nxt
        merged[b] = level[0]

    def reading(region: list, h: int) -> list:
        """The merged regions holding tiles within ``h`` of ``region``."""
        x0 = min(t[0] for t in region) - h
        x1 = max(t[0] for t in region) + h
        y0 = min(t[1] for t in region) - h
        y1 = max(t[1] for t in region) + h
        return [
            b
            for b in merged
            if ox + b[0] * side <= x1 and ox + (b[0] + 1) * side - 1 >= x0
            and oy + b[1] * side <= y1 and oy + (b[1] + 1) * side - 1 >= y0
        ]

    pending = [
        (
            [(ox + bx * side + i, oy + by * side + j) for i in range(side) for j in range(side)],
            halo,
        )
        for (bx, by) in sorted(merged)
    ]
    crops_all = []
    finished = []
    regions_done = []
    refinished = 0
    largest = halo
    while pending:
        futures = []
        for region, h in pending:
            crops = [
                client.submit(_near, merged[b], region, h, pure=False)
                for b in reading(region, h)
            ]
            crops_all.extend(crops)
            futures.append(
                client.submit(_finish, crops, region, h, bounds, cfg, alarms, pure=False)
            )
        done = client.gather(futures)
        finished.extend(futures)
        regions_done.extend(done)
        nxt = []
        for (region, h), r in zip(pending, done):
            if r.undecided:
                if h >= extent:
                    raise RuntimeError(
                        f"{len(r.undecided)} tiles undecided with a halo of {h} tiles over a "
                        f"map {extent} tiles across"
                    )
                refinished += len(r.undecided)
                largest = max(largest, min(2 * h, extent))
                nxt.append((list(r.undecided), min(2 * h, extent)))
        pending = nxt
    m = tarn.join_regions(regions_done)
    t1 = time.perf_counter()
    if stats is not None:

        def total(futures):
            sizes = client.gather([client.submit(_nbytes, f, pure=False) for f in futures])
            return int(sum(sizes))

        # Each per-log part goes into a merge (or straight to the finishes when it is
        # alone); each merge result into the next merge or to the finishes; cuts of the
        # merged regions into the finishes; the finished regions to the client.
        stats["log_bytes"] = total(picks)
        stats["merge_bytes"] = total(merges)
        stats["halo_bytes"] = total(crops_all)
        stats["result_bytes"] = total(finished)
        stats["points"] = int(
            sum(client.gather([client.submit(_points, f, pure=False) for f in per_log]))
        )
        stats["parts"] = len(merged)
        stats["refinished_tiles"] = refinished
        stats["largest_halo"] = largest
        stats["most_tiles_read"] = max(r.tiles_read for r in regions_done)
        stats["seconds"] = t1 - t0
    return m


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tarn.dask",
        description="Builds the map of many logs on a Dask cluster and writes map.ply, "
        "terrain.ply, water.ply and map.png into --out.",
    )
    ap.add_argument("logs", nargs="+", metavar="LOG", help="ROS 2 logs (.mcap)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--config", help="tarn.toml (default: what `tarn build` uses)")
    ap.add_argument("--scheduler", help="address of a running scheduler (default: a LocalCluster)")
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster workers (default 2)")
    ap.add_argument(
        "--threads",
        action="store_true",
        help="LocalCluster workers as threads of this process (processes=False)",
    )
    ap.add_argument(
        "--parts",
        type=int,
        help="regions: at most ceil(sqrt(N)) a side (default: worker threads)",
    )
    ap.add_argument("--region-tiles", type=int, help="side of a region, tiles (overrides --parts)")
    ap.add_argument("--halo", type=int, default=2, help="tiles read around a region (default 2)")
    a = ap.parse_args(argv)

    from dask.distributed import Client, LocalCluster

    cluster = None
    if a.scheduler:
        client = Client(a.scheduler)
    else:
        cluster = LocalCluster(
            n_workers=a.workers,
            threads_per_worker=1,
            processes=not a.threads,
            dashboard_address=None,
        )
        client = Client(cluster)
    try:
        stats: dict = {}
        m = build_many(
            a.logs,
            client,
            config=a.config,
            parts=a.parts,
            stats=stats,
            region_tiles=a.region_tiles,
            halo=a.halo,
        )
        m.write(a.out)
    except (tarn.TarnError, OSError, ValueError) as e:
        print(f"python -m tarn.dask: {e}", file=sys.stderr)
        return 1
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    print(
        f"{len(a.logs)} logs: {len(m)} cells, {len(m.bodies)} water bodies -> {a.out}; "
        f"{stats['parts']} regions, {stats['refinished_tiles']} tiles finished again; "
        f"{stats['log_bytes'] + stats['merge_bytes'] + stats['halo_bytes']} bytes of tile "
        f"sets and {stats['result_bytes']} bytes of finished regions for {stats['points']} "
        "points"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
