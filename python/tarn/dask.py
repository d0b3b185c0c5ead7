"""Offline builds of many logs on a Dask cluster.

``build_many(logs, client)``:

1. one task per log builds its ``TileSet`` (``tarn.build_tiles``; the Rust code releases
   the interpreter, so threaded workers build in parallel) and splits it by tile key into
   ``parts`` regions (``TileSet.partition``: a fixed hash of the tile key, the same in every
   process);
2. each region is tree-reduced on the workers: pairwise merges, ``log(n)`` levels deep;
3. the client gathers the ``parts`` merged regions, joins them (they share no tile) and runs
   the water stage once over the whole merged map (``tarn.finish``), so a water body cut by
   log, tile or region borders is found whole.

Merging is exact (integer sums), so the map is byte-identical to ``tarn.build_many`` in one
process, for any number of workers and any order the merges run in. Logs are the unit of
work: time chunks of one log would not merge to its one-pass map (a frame's cues read the
window the earlier frames left), so a log is never split.

Command line: ``python -m tarn.dask LOG... --out DIR [--scheduler ADDRESS]`` (a
``LocalCluster`` by default).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any, Optional, Sequence

import tarn

__all__ = ["build_many", "main"]


def _tiles_of_log(path: str, config: Optional[str], parts: int) -> list:
    return tarn.build_tiles(path, config).partition(parts)


def _pick(parts: list, i: int):
    return parts[i]


def _merge2(a, b):
    # A new set: with threaded workers a task's inputs are shared objects.
    out = a.copy()
    out.merge(b)
    return out


def _nbytes(t) -> int:
    return len(t.to_bytes())


def _points(parts: list) -> int:
    return sum(p.points for p in parts)


def build_many(
    logs: Sequence[str | os.PathLike],
    client: Any,
    config: Optional[str | os.PathLike] = None,
    parts: Optional[int] = None,
    stats: Optional[dict] = None,
) -> "tarn.Map":
    """The map of ``logs`` built on the Dask ``client``'s cluster (see the module doc).

    ``config``: a ``tarn.toml`` path readable by the workers (``None``: what ``tarn build``
    uses). ``parts``: regions the reduction is split into (default: the cluster's worker
    threads, at least 1). ``stats``: a dict to fill with what travelled: ``log_bytes`` (the
    per-log tile sets, as bytes), ``merge_bytes`` (the merged sets each merge produced),
    ``result_bytes`` (what the client gathered), ``points`` (points in the logs' cells),
    ``parts``, and ``seconds`` (wall time of build and reduction, and of the water stage).
    """
    paths = [os.fspath(p) for p in logs]
    if not paths:
        raise ValueError("no logs to build")
    cfg = None if config is None else os.fspath(config)
    if parts is None:
        nthreads = client.nthreads() if hasattr(client, "nthreads") else {}
        parts = max(1, sum(nthreads.values()))
    t0 = time.perf_counter()
    per_log = [
        client.submit(_tiles_of_log, p, cfg, parts, key=f"tarn-tiles-{i}", pure=False)
        for i, p in enumerate(paths)
    ]
    picks = []
    merges = []
    roots = []
    for r in range(parts):
        level = [client.submit(_pick, f, r, pure=False) for f in per_log]
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
        roots.append(level[0])
    if stats is not None:

        def total(futures):
            sizes = client.gather([client.submit(_nbytes, f, pure=False) for f in futures])
            return int(sum(sizes))

        # Each per-log part goes into a merge (or to the client when it is alone); each
        # merge result into the next merge or to the client.
        stats["log_bytes"] = total(picks)
        stats["merge_bytes"] = total(merges)
        stats["result_bytes"] = total(roots)
        stats["points"] = int(
            sum(client.gather([client.submit(_points, f, pure=False) for f in per_log]))
        )
        stats["parts"] = parts
    merged = client.gather(roots)
    whole = tarn.merge(merged)
    t1 = time.perf_counter()
    m = tarn.finish(whole, cfg)
    t2 = time.perf_counter()
    if stats is not None:
        stats["seconds"] = {"build_and_reduce": t1 - t0, "water": t2 - t1}
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
    ap.add_argument("--parts", type=int, help="regions of the reduction (default: worker threads)")
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
        m = build_many(a.logs, client, config=a.config, parts=a.parts, stats=stats)
        m.write(a.out)
    except (tarn.TarnError, OSError) as e:
        print(f"python -m tarn.dask: {e}", file=sys.stderr)
        return 1
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    print(
        f"{len(a.logs)} logs: {len(m)} cells, {len(m.bodies)} water bodies -> {a.out}; "
        f"{stats['log_bytes'] + stats['merge_bytes'] + stats['result_bytes']} bytes of tile "
        f"sets for {stats['points']} points"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
