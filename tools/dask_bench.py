"""Measures `tarn.dask.build_many` on this machine: wall time with 1, 2 and 4 workers
against the one-process build, the bytes of tile sets that travel per million points, and
the finished regions the client gathers.
Writes the tables of docs/distributed.md to stdout (markdown).

    .venv/bin/python tools/dask_bench.py [--logs 4] [--frames 12] [--workers 1,2,4]

The logs are simulated with `tarn simulate` (TARN_BIN, default target/debug/tarn) from
maps/default.toml with drives along parallel lines past the pond.
"""

import argparse
import os
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

import tarn
import tarn.dask

ROOT = pathlib.Path(__file__).resolve().parent.parent


def cpu_s() -> float:
    """CPU time of this process, every thread, user and system (s)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(f):
    """`f()`, its wall time and the CPU time it took (s)."""
    t, c = time.perf_counter(), cpu_s()
    r = f()
    return r, time.perf_counter() - t, cpu_s() - c


def tarn_bin() -> str:
    return os.environ.get("TARN_BIN") or str(ROOT / "target" / "debug" / "tarn")


def simulate(d: pathlib.Path, n: int, frames: int) -> list:
    text = (ROOT / "maps" / "default.toml").read_text()
    head, _ = text.split("[trajectory]")
    head = head.replace('rig = "rigs/small.toml"', f'rig = "{ROOT / "maps" / "rigs" / "small.toml"}"')
    logs = []
    for i in range(n):
        y = -4.0 + 18.0 * i / max(1, n - 1)
        s = d / f"drive{i}.toml"
        s.write_text(
            head
            + f"[trajectory]\nwaypoints = [[2.0, {y}], [40.0, {y}]]\nspeed = 3.0\n"
            f"rate_hz = 5.0\nframes = {frames}\n"
        )
        out = d / f"drive{i}"
        subprocess.run([tarn_bin(), "simulate", str(s), "--out", str(out)], check=True, capture_output=True)
        logs.append(str(out / "log.mcap"))
    return logs


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", type=int, default=4)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--repeat", type=int, default=2, help="runs per row; the fastest is kept")
    a = ap.parse_args()
    from dask.distributed import Client, LocalCluster

    with tempfile.TemporaryDirectory() as tmp:
        logs = simulate(pathlib.Path(tmp), a.logs, a.frames)
        best = None
        for _ in range(a.repeat):
            ref, dt, cpu = timed(lambda: tarn.build_many(logs))
            if best is None or dt < best:
                best, best_cpu = dt, cpu
        ref_bytes = ref.ply_bytes()
        # The one-process build's phases: what a worker does in parallel (a log's build)
        # and what is left after it (merge, water stage), with the CPU time of each.
        sets, *build = timed(lambda: [tarn.build_tiles(p) for p in logs])
        merged, *merge = timed(lambda: tarn.merge(sets))
        _, *finish = timed(lambda: tarn.finish(merged))
        phases = [("build_tiles of each log", *build), ("merge", *merge), ("finish (water stage)", *finish)]
        del sets, merged
        rows = []
        for w in [int(x) for x in a.workers.split(",")]:
            cluster = LocalCluster(n_workers=w, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
            try:
                # Warm the workers (imports) before timing.
                tarn.dask.build_many(logs[:1], client)
                times = []
                for _ in range(a.repeat):
                    stats = {}
                    t = time.perf_counter()
                    m = tarn.dask.build_many(logs, client)
                    times.append(time.perf_counter() - t)
                assert m.ply_bytes() == ref_bytes, "the Dask map differs from the one-process map"
                stats = {}
                tarn.dask.build_many(logs, client, stats=stats)
            finally:
                client.close()
                cluster.close()
            rows.append((w, min(times), stats))
        pts = rows[0][2]["points"]
        print(f"{a.logs} logs, {a.frames} frames each, {pts:,} points in their cells; "
              f"one-process `tarn.build_many`: {best:.2f} s ({pts / best:,.0f} points/s), "
              f"{best_cpu:.2f} s of CPU ({best_cpu / best:.2f} cores busy)\n")
        print("| one-process phase | wall time | CPU time | cores busy |")
        print("| --- | --- | --- | --- |")
        for name, w, c in phases:
            print(f"| {name} | {w:.2f} s | {c:.2f} s | {c / w:.2f} |")
        print()
        print("| workers | wall time / one-process time | speed-up over 1 worker | map identical |")
        print("| --- | --- | --- | --- |")
        for w, t, _ in rows:
            print(f"| {w} | {t / best:.2f} | {rows[0][1] / t:.2f} | yes |")
        print()
        print("| workers | regions | per-log parts → merges | merge results | halo cuts → finishes | tile sets in all | per million points | finished regions gathered by the client | tiles finished again |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for w, _, s in rows:
            tot = s["log_bytes"] + s["merge_bytes"] + s["halo_bytes"]
            print(
                f"| {w} | {s['parts']} | {s['log_bytes']:,} | {s['merge_bytes']:,} | "
                f"{s['halo_bytes']:,} | {tot:,} | {tot / (s['points'] / 1e6):,.0f} | "
                f"{s['result_bytes']:,} | {s['refinished_tiles']} |"
            )
        one = tarn.merge([tarn.build_tiles(p) for p in logs])
        print(f"\nmerged map: {len(one)} cells, {one.tile_count} tiles, "
              f"{len(one.to_bytes()):,} bytes as a tile set ({len(one.to_bytes()) / len(one):.1f} bytes/cell); "
              f"one log on its own: {len(tarn.build_tiles(logs[0]).to_bytes()):,} bytes for "
              f"{tarn.build_tiles(logs[0]).points:,} points")
    return 0


if __name__ == "__main__":
    sys.exit(main())
