"""Issue 16 scaling benchmark: the whole ``python -m core flatten`` process on the ``bump`` surface from
33k to 2M triangles (4M with ``--with-4m``), wall time and peak memory, per solver backend.

    .venv/bin/python bench/scale.py                          # 33k .. 2M, area and uniform, both backends
    .venv/bin/python bench/scale.py --sizes 1000000 --modes area --solvers cholmod
    .venv/bin/python bench/scale.py --with-4m --modes area --solvers cholmod

Each case is one child process, timed from spawn to exit (interpreter start, imports, OBJ read,
flatten, OBJ write), with its own peak resident set size from ``os.wait4``; ``--repeat`` runs every
case that many times, interleaved (one round over all cases, then the next), and takes the medians.
The children keep Python's bytecode caches, as a user's installation does. The report's own timings
(``--json``) split the core's part: factor, solve, total. The input OBJ files are written once into
``--cache`` (default: a folder under the system temp dir). ``--solvers`` runs each case with
``CONFORMAL_SOLVER`` set (``auto``: the core chooses by size; ``superlu`` or ``cholmod`` force one
backend).
The anchors printed with the table are the BFF command-line tool's figures measured on this machine
for issue 16 (BFF's binary is not shipped here): wall time 0.35 s at 33k, 1.78 s at 100k, 8.5 s at
403k, 18.9 s at 1M; peak memory 1.33 GB at 1M.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

BFF_SECONDS = {129: 0.35, 225: 1.78, 450: 8.5, 708: 18.9}     # issue 16, same machine
BFF_PEAK_MB = {708: 1.33 * 1024}
SIZES = [33_000, 100_000, 403_000, 1_000_000, 2_000_000]     # n = 129, 225, 450, 708, 1001


def grid_n(triangles):
    """Grid size n of the bump surface with about ``triangles`` = 2 (n-1)^2 triangles."""
    return int(round((triangles / 2) ** 0.5)) + 1


def mesh_file(cache, n):
    """Path of the bump OBJ with grid size n in ``cache``, written on first use."""
    path = os.path.join(cache, f'bump_{n}.obj')
    if not os.path.exists(path):
        from core.io.obj import write_obj
        from core.surfaces import make_surface
        V, F = make_surface('bump', n)
        write_obj(path, V, F)
    return path


def run_process(argv, env):
    """Run ``argv``; return (wall seconds, peak RSS MB, stdout, CPU seconds). Raises on a non-zero exit."""
    t = time.perf_counter()
    with tempfile.TemporaryFile() as errf:
        p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=errf, env=env)
        out = p.stdout.read()
        _, status, usage = os.wait4(p.pid, 0)      # this child's own rusage (peak RSS)
        wall = time.perf_counter() - t
        code = os.waitstatus_to_exitcode(status)
        if code:
            errf.seek(0)
            raise RuntimeError(f"{' '.join(argv)} exited {code}: {errf.read().decode()[-400:]}")
    return wall, usage.ru_maxrss / 1024, out.decode(), usage.ru_utime + usage.ru_stime


def startup_seconds(env):
    """Wall time of a process that only starts Python and imports what the flatten command uses."""
    code = 'import core.cli.flatten'
    return min(run_process([sys.executable, '-c', code], env)[0] for _ in range(3))


def load_note():
    """The 1-minute load average against the core count: timings are only comparable on an idle machine."""
    try:
        return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    except OSError:
        return ''


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--sizes', type=int, nargs='+', default=SIZES, help='target triangle counts')
    ap.add_argument('--with-4m', action='store_true', help='add the 4M-triangle case (measured 7.7 GB peak)')
    ap.add_argument('--modes', nargs='+', default=['area', 'uniform'], choices=['free', 'area', 'uniform'])
    ap.add_argument('--solvers', nargs='+', default=['auto'], choices=['auto', 'cholmod', 'superlu'],
                    help='auto: the core\'s own choice by size; the others force one backend')
    ap.add_argument('--uniform-max', type=int, default=1_000_000,
                    help='run uniform only up to this many triangles')
    ap.add_argument('--repeat', type=int, default=1, help='runs per case (median reported)')
    ap.add_argument('--cache', default=os.path.join(tempfile.gettempdir(), 'conformal-scale-bench'))
    args = ap.parse_args()
    sizes = list(args.sizes) + ([4_000_000] if args.with_4m else [])
    os.makedirs(args.cache, exist_ok=True)
    from core.mesh.solve import backend
    print(f"backend available here: {backend()} (python {sys.version.split()[0]})")
    print("BFF anchors (issue 16, BFF binary not available here): "
          + ', '.join(f"n={n} {s} s" for n, s in BFF_SECONDS.items()) + ", 1.33 GB peak at 1M")
    # as on a user's machine: Python keeps its bytecode caches (a development shell may turn them off)
    env0 = {k: v for k, v in os.environ.items() if k != 'PYTHONDONTWRITEBYTECODE'}
    env0['PYTHONPATH'] = ROOT + os.pathsep + os.environ.get('PYTHONPATH', '')
    run_process([sys.executable, '-m', 'core', 'flatten', '--help'], env0)      # writes the caches
    print(f"interpreter start + imports: {startup_seconds(env0):.2f} s; {load_note()}")
    cases = []
    for size in sizes:
        n = grid_n(size)
        for mode in args.modes:
            if mode == 'uniform' and size > args.uniform_max:
                continue
            cases += [(n, mode, solver) for solver in args.solvers]
    # interleaved: every case once per round, so a change of load hits all of them alike
    runs = {c: [] for c in cases}
    failed = {}
    for _ in range(args.repeat):
        for case in cases:
            n, mode, solver = case
            if case in failed:
                continue
            path = mesh_file(args.cache, n)
            out_path = os.path.join(args.cache, f'out_{n}.obj')
            env = dict(env0, CONFORMAL_SOLVER=solver)
            argv = [sys.executable, '-m', 'core', 'flatten', path, out_path, '--boundary', mode, '--json']
            try:
                wall, peak, out, cpu = run_process(argv, env)
                runs[case].append((wall, peak, json.loads(out.strip().splitlines()[-1]), cpu))
            except RuntimeError as exc:
                failed[case] = exc
            if os.path.exists(out_path):
                os.remove(out_path)
    print(f"medians of {args.repeat} interleaved runs; {load_note()}")
    print("| triangles | mode | solver | wall s | CPU s | core total s | factor s | solve s | I/O+start s "
          "| peak MB | vs BFF time | vs BFF mem | mu_ratio | qc_mean | flips |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for case in cases:
        n, mode, solver = case
        if case in failed:
            print(f"| {2 * (n - 1) ** 2:,} | {mode} | {solver} | failed: {failed[case]} |")
            continue
        rs = sorted(runs[case], key=lambda r: r[0])
        wall, peak, rep, cpu = rs[len(rs) // 2]
        sec = rep['seconds']
        bff = BFF_SECONDS.get(n)
        bff_m = BFF_PEAK_MB.get(n)
        peak = statistics.median(r[1] for r in rs)
        print(f"| {rep['faces']:,} | {mode} | {rep.get('solver', solver)} | {wall:.2f} | {cpu:.2f} | "
              f"{sec['total']:.2f} | {sec['factor']:.2f} | {sec['solve']:.2f} | "
              f"{wall - sec['total']:.2f} | {peak:.0f} | "
              f"{f'{wall / bff:.2f}x' if bff else ''} | {f'{peak / bff_m:.2f}x' if bff_m else ''} | "
              f"{rep['mu_ratio']:.4f} | {rep['qc_mean']:.4f} | {rep['flips']} |", flush=True)


if __name__ == '__main__':
    main()
