"""
Campaign throughput: runs per second in-process, on a local two-node Ray cluster.

Usage: python bench/campaign.py [--file config/campaigns/paper_vertical_10k.yaml]
[--scalar-runs 5] [--no-ray] [--no-kill]

1. The scalar offline runner (``offline.run_case``, vertical, robust) over a few seeds:
   seconds per run.
2. The campaign in this process (one worker, numba threads on every core): wall time,
   runs/s, CPU time, the ratio to the scalar runner.
3. A two-node Ray cluster on this machine (``ray start --head --port P`` on 127.0.0.1 and
   ``ray start --address 127.0.0.1:P``, one CPU each, their own temp folder, started with
   ``--block`` as children of this script and stopped by their process group at the end):
   the same campaign with ``--address``; its results.parquet compared byte for byte with
   the in-process one.
4. Again on the cluster, killing one Ray worker process (SIGKILL, a descendant of the
   cluster this script started) once two chunks are written: the campaign completes, and
   the table is again byte-identical (every run exactly once: ``campaign.merge`` checks it).

Prints the figures with the load average (the machine is shared); asserts nothing.
Also ``run()`` for bench/run_all.py is not provided: this bench takes minutes.
"""
import argparse
import os
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def _free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _scalar(n):
    from freejoint_core.offline import run_case
    t0 = time.perf_counter()
    for seed in range(n):
        run_case('vertical', 'robust', seed)
    return (time.perf_counter() - t0) / n


def _campaign(file, out, address=None, wait=True):
    cmd = [sys.executable, '-m', 'freejoint_tools.campaign', 'run', file, '--out', out,
           '--no-progress']
    if address:
        cmd += ['--address', address]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if wait:
        out_text, err = proc.communicate()
        return proc.returncode, out_text, err
    return proc


def _descendants(pid):
    """Return the PIDs of every process below ``pid`` (from /proc)."""
    children = {}
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                with open(f'/proc/{entry}/stat') as f:
                    ppid = int(f.read().rsplit(')', 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


def _cmdline(pid):
    try:
        with open(f'/proc/{pid}/cmdline', 'rb') as f:
            return f.read().replace(b'\0', b' ').decode(errors='replace')
    except OSError:
        return ''


class Cluster:
    """A two-node Ray cluster on 127.0.0.1 started by this process (stopped by ``close``)."""

    def __init__(self):
        # Ray 2.60 authenticates with a token: ours, for this cluster and its drivers only.
        os.environ['RAY_AUTH_MODE'] = 'token'
        os.environ['RAY_AUTH_TOKEN'] = secrets.token_hex(32)
        self.head = self.node = None
        self.port = _free_port()
        self.address = f'127.0.0.1:{self.port}'
        self.tmp = tempfile.mkdtemp(prefix='ray_bench_')

    def start(self):
        """Start the head, wait for it, add the second node, wait for both."""
        ray = os.path.join(os.path.dirname(sys.executable), 'ray')
        common = ['--num-cpus', '1', '--block', '--disable-usage-stats']
        self.head = subprocess.Popen(
            [ray, 'start', '--head', '--port', str(self.port), '--node-ip-address', '127.0.0.1',
             '--include-dashboard', 'false', '--temp-dir', self.tmp] + common,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        self._wait_nodes(1)
        self.node = subprocess.Popen(
            [ray, 'start', '--address', self.address, '--node-ip-address', '127.0.0.1'] + common,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        self._wait_nodes(2)

    def _wait_nodes(self, n, timeout=180.0):
        code = ('import ray,sys; ray.init(address=sys.argv[1], log_to_driver=False, '
                'configure_logging=False); '
                'print(sum(1 for x in ray.nodes() if x["Alive"])); ray.shutdown()')
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            done = subprocess.run([sys.executable, '-c', code, self.address],
                                  capture_output=True, text=True, timeout=120)
            if done.returncode == 0 and done.stdout.strip().splitlines()[-1:] == [str(n)]:
                return
            time.sleep(2.0)
        raise RuntimeError(f'the Ray cluster did not reach {n} nodes in {timeout} s')

    def pids(self):
        """Return the PIDs of the cluster's processes."""
        return [self.head.pid, self.node.pid] + _descendants(self.head.pid) \
            + _descendants(self.node.pid)

    def close(self):
        """Stop both nodes: SIGTERM to each ``ray start``, then SIGKILL to its group."""
        procs = [p for p in (self.node, self.head) if p is not None]
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()


def _same(a, b):
    with open(os.path.join(a, 'results.parquet'), 'rb') as fa, \
            open(os.path.join(b, 'results.parquet'), 'rb') as fb:
        return fa.read() == fb.read()


def main(argv=None):
    """Run the bench and print its figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument('--file', default=os.path.join(ROOT, 'config', 'campaigns',
                                                   'paper_vertical_10k.yaml'))
    ap.add_argument('--scalar-runs', type=int, default=5)
    ap.add_argument('--no-ray', action='store_true')
    ap.add_argument('--no-kill', action='store_true')
    ap.add_argument('--inprocess-dir', default=None,
                    help='results folder of an in-process run of the same file (skips it)')
    args = ap.parse_args(argv)
    from freejoint_tools import campaign
    camp = campaign.load(args.file)
    n = len(campaign.design(camp)['run_index'])
    work = tempfile.mkdtemp(prefix='campaign_bench_')
    print(f'campaign {camp["name"]}: {n} runs of {camp["duration"]:g} s ({camp["case"]}), '
          f'{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at start')
    # Warm the numba cache so no figure includes compilation.
    campaign.run_chunk(camp, {k: v[:2] for k, v in campaign.design(camp).items()})
    per_scalar = _scalar(args.scalar_runs)
    print(f'scalar offline runner: {per_scalar:.3f} s per run ({1 / per_scalar:.2f} runs/s, '
          f'{args.scalar_runs} runs), load {os.getloadavg()[0]:.2f}')
    inproc = args.inprocess_dir or os.path.join(work, 'inprocess')
    t0 = time.perf_counter()
    c0 = os.times()
    if not args.inprocess_dir:
        code, _, err = _campaign(args.file, inproc)
        wall = time.perf_counter() - t0
        c1 = os.times()
        cpu = (c1.children_user + c1.children_system) - (c0.children_user + c0.children_system)
        print(f'in-process (1 worker, all cores): {wall:.1f} s wall, {n / wall:.0f} runs/s, '
              f'{cpu:.1f} s CPU, {n / wall * per_scalar:.0f}x the scalar runner, load '
              f'{os.getloadavg()[0]:.2f}' + ('' if code == 0 else f'  FAILED: {err.strip()}'))
    if args.no_ray:
        return 0
    cluster = None
    try:
        cluster = Cluster()
        cluster.start()
        print(f'Ray cluster up: {cluster.address}, 2 nodes, load {os.getloadavg()[0]:.2f}',
              flush=True)
        ray_dir = os.path.join(work, 'ray')
        t0 = time.perf_counter()
        code, _, err = _campaign(args.file, ray_dir, cluster.address)
        wall = time.perf_counter() - t0
        print(f'Ray, two local nodes x 1 CPU: {wall:.1f} s wall, {n / wall:.0f} runs/s, '
              f'{n / wall * per_scalar:.0f}x the scalar runner, load '
              f'{os.getloadavg()[0]:.2f}; results byte-identical to in-process: '
              f'{code == 0 and _same(inproc, ray_dir)}' + ('' if code == 0 else f' {err}'))
        if not args.no_kill:
            kill_dir = os.path.join(work, 'ray_kill')
            proc = _campaign(args.file, kill_dir, cluster.address, wait=False)
            chunks = os.path.join(kill_dir, 'chunks')
            killed = None
            deadline = time.monotonic() + 600
            while killed is None and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.2)
                if os.path.isdir(chunks) and len(os.listdir(chunks)) >= 2:
                    for pid in cluster.pids():
                        if 'ray::_ray_task' in _cmdline(pid):
                            os.kill(pid, signal.SIGKILL)
                            killed = pid
                            break
            out_text, err = proc.communicate()
            print(f'Ray with worker {killed} killed after 2 chunks: exit {proc.returncode}, '
                  f'results byte-identical to in-process (each run once): '
                  f'{proc.returncode == 0 and _same(inproc, kill_dir)}'
                  + ('' if proc.returncode == 0 else f' {err.strip()[-300:]}'))
    finally:
        if cluster is not None:
            cluster.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
