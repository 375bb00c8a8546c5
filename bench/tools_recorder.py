"""
Benchmark: the recorder node's throughput without loss, and the bag tools' speed.

Figures (printed; nothing is asserted):

* for increasing rates, a publisher process (test/nodes/tools_publisher.py, 4 messages per
  tick: /clock, joint_states, setpoint, controller_state, reliable depth 100; the graph's
  is 1000)
  runs 2 s of ticks while a recorder process records all topics; the messages the bag
  holds are counted against those published: the highest rate with no loss (msg/s; target
  >= 4000, the 1 kHz lockstep graph's four topics), the loss at each rate, and the
  recorder's CPU time per message (us, from /proc); with ``--sim-time`` the recorder runs
  with ``use_sim_time:=true`` (log times from the recorded /clock, as in the graph);
* in-process: BagWriter messages/s, open_bag + decode + record of a 5-s run (5000 ticks).

Usage: ``. tools/env.sh && python bench/tools_recorder.py [--sim-time] [--rates 1000,4000]
[--recorder 'CMD ...']`` (needs the built workspace; ``--recorder`` runs another recorder
command, e.g. a copy of an older version for an A/B pair).
"""

import argparse
import json
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import time

from freejoint_common.contract import CLOCK, CONTROLLER_STATE, JOINT_STATES, SETPOINTS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECORDER = os.path.join(ROOT, 'install', 'freejoint_tools', 'lib', 'freejoint_tools',
                        'recorder')
PUBLISHER = os.path.join(ROOT, 'test', 'nodes', 'tools_publisher.py')
TICK_RATES = (1000, 2000, 4000, 8000)
SECONDS = 2.0
TICK_TOPICS = tuple(t.absolute for t in (CLOCK, JOINT_STATES, SETPOINTS, CONTROLLER_STATE))


def _env():
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(150 + os.getpid() % 80)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    return env


def _cpu_seconds(pid):
    with open('/proc/%d/stat' % pid) as fh:
        fields = fh.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _one_rate(tmp, tick_rate, recorder_cmd, sim_time):
    from freejoint_tools.bagfile import open_bag
    env = _env()
    bag = os.path.join(tmp, 'rate_%d' % tick_rate)
    summary = os.path.join(tmp, 'published_%d.json' % tick_rate)
    params = ['-p', 'use_sim_time:=true'] if sim_time else []
    recorder = subprocess.Popen(recorder_cmd + ['--ros-args', '-p', 'output:=%s' % bag,
                                                '-p', 'topics:=[]', *params],
                                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    hung = False
    try:
        ticks = int(tick_rate * SECONDS)
        cpu0 = None
        publisher = subprocess.Popen(
            [sys.executable, PUBLISHER, '--ticks', str(ticks), '--rate', str(tick_rate),
             '--clock', '--summary', summary], env=env, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True)
        for line in publisher.stdout:
            if 'publishing' in line and cpu0 is None:
                cpu0 = _cpu_seconds(recorder.pid)
        publisher.wait(120)
        cpu1 = _cpu_seconds(recorder.pid)
    finally:
        recorder.send_signal(signal.SIGINT)
        try:
            recorder.wait(60)
        except subprocess.TimeoutExpired:   # a hung recorder: its bag is not finalised
            hung = True
            recorder.kill()
            recorder.wait(10)
    with open(summary) as fh:
        published = json.load(fh)
    sent = sum(published['topics'][t]['count'] for t in TICK_TOPICS)
    topics = open_bag(bag).topics
    kept = sum(topics[t].count if t in topics else 0 for t in TICK_TOPICS)
    return {'offered': sent / published['seconds'], 'sent': sent, 'kept': kept,
            'cpu_us': 1e6 * (cpu1 - (cpu0 or cpu1)) / max(kept, 1), 'hung': hung}


def _bag_tools(tmp):
    """In-process: writer speed, and open + decode + record of a 5000-tick bag."""
    sys.path.insert(0, os.path.join(ROOT, 'test', 'tools'))
    from conftest import _load_publisher, BagMaker
    from freejoint_tools.analyze import analyse_bag
    maker = BagMaker(_load_publisher())
    path = os.path.join(tmp, 'horizontal')
    start = time.perf_counter()
    written = maker(path, 5000, custom_data={'case': 'horizontal', 'variant': 'robust'})
    write_s = time.perf_counter() - start
    count = sum(len(v) for v in written.values())
    start = time.perf_counter()
    analyse_bag(path)
    return count, write_s, time.perf_counter() - start


def run(rates=TICK_RATES, recorder_cmd=None, sim_time=False):
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    rows = []
    best = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for tick_rate in rates:
            r = _one_rate(tmp, tick_rate, recorder_cmd or [RECORDER], sim_time)
            if r['hung']:
                rows.append({'name': 'recorder at %d ticks/s: hung at SIGINT (killed)'
                             % tick_rate, 'value': 1, 'unit': '', 'target': '<= 0'})
            lost = r['sent'] - r['kept']
            if lost == 0:
                best = max(best, r['offered'])
            rows.append({'name': 'recorder at %d ticks/s: offered msg/s' % tick_rate,
                         'value': r['offered'], 'unit': 'msg/s', 'target': None})
            rows.append({'name': 'recorder at %d ticks/s: messages lost of %d'
                         % (tick_rate, r['sent']), 'value': lost, 'unit': 'msg',
                         'target': '<= 0' if tick_rate <= 1000 else None})
            rows.append({'name': 'recorder at %d ticks/s: CPU per message' % tick_rate,
                         'value': r['cpu_us'], 'unit': 'us', 'target': None})
        rows.insert(0, {'name': 'recorder throughput without loss (highest offered)',
                        'value': best, 'unit': 'msg/s', 'target': '>= 4000'})
        count, write_s, analyse_s = _bag_tools(tmp)
    rows.append({'name': 'BagWriter in-process (serialize + write)',
                 'value': count / write_s, 'unit': 'msg/s', 'target': None})
    rows.append({'name': 'analyze: open + decode + record of a 5000-tick bag',
                 'value': analyse_s, 'unit': 's', 'target': '<= 5'})
    return rows


def main():
    """Print the rows; see the module notes for the options."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sim-time', action='store_true',
                        help='run the recorder with use_sim_time:=true')
    parser.add_argument('--rates', default=','.join(str(r) for r in TICK_RATES),
                        help='tick rates (ticks/s, 4 messages per tick), comma-separated')
    parser.add_argument('--recorder', default='',
                        help='recorder command to run instead of the installed one')
    args = parser.parse_args()
    rates = [int(r) for r in args.rates.split(',') if r]
    for row in run(rates, shlex.split(args.recorder) or None, args.sim_time):
        print('%-58s %12.4g %-6s %s' % (row['name'], row['value'], row['unit'],
                                        row['target'] or ''))


if __name__ == '__main__':
    main()
