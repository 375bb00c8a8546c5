"""freejoint_tools.harness.Processes: the process harness of the demo, the bench and the tests."""
import os
import signal
import sys

from freejoint_tools.harness import node_cmd, Processes

CLAIMER = ('import sys, time\n'
           'from freejoint_tools.harness import claim_ros_domain\n'
           'print(claim_ros_domain(5, first=1, count=6, lock_dir=sys.argv[1]), flush=True)\n'
           'time.sleep(60 if sys.argv[2:] else 0)\n')

SLEEPER = ('import signal, sys, time\n'
           'signal.signal(signal.SIGINT, lambda *a: sys.exit(7))\n'
           'print("up", flush=True)\n'
           'time.sleep(60)\n')
STUBBORN = ('import signal, time\n'
            'signal.signal(signal.SIGINT, signal.SIG_IGN)\n'
            'print("up", flush=True)\n'
            'time.sleep(60)\n')


def test_exited_names_only_the_processes_that_have_exited(tmp_path, wait):
    procs = Processes(str(tmp_path), tag='run')
    try:
        quick = procs.start('quick', [sys.executable, '-c', 'print("bye"); raise SystemExit(3)'])
        procs.start('sleeper', [sys.executable, '-c', SLEEPER])
        wait(lambda: quick.poll() is not None, 30.0, 'the quick process to exit')
        wait(lambda: 'up' in procs.log('sleeper'), 30.0, 'the sleeper to start')
        assert procs.exited() == ['quick']
        assert procs.log(quick) == 'bye\n'
        assert quick.log_path == str(tmp_path / 'run_quick.log')
    finally:
        codes = procs.stop_all()
    assert codes == {'sleeper': 7, 'quick': 3}


def test_stop_all_goes_in_the_given_order_and_kills_what_ignores_sigint(tmp_path, wait):
    procs = Processes(str(tmp_path), stop_timeout=0.5)
    stubborn = procs.start('stubborn', [sys.executable, '-c', STUBBORN])
    procs.start('sleeper', [sys.executable, '-c', SLEEPER])
    wait(lambda: 'up' in procs.log('stubborn') and 'up' in procs.log('sleeper'), 30.0,
         'both to start')
    codes = procs.stop_all(order=('stubborn',))
    assert list(codes) == ['stubborn', 'sleeper']
    assert codes['stubborn'] == -9 and stubborn.log_file.closed
    assert codes['sleeper'] == 7
    assert procs.stop_all() == {}     # nothing left to stop


def test_the_environment_reaches_the_process_and_a_restart_keeps_both_logs(tmp_path, wait):
    procs = Processes(str(tmp_path), env={'FREEJOINT_X': 'base', 'PATH': '/usr/bin:/bin'})
    show = [sys.executable, '-c', 'import os; print(os.environ["FREEJOINT_X"], '
            'os.environ["ROS_DOMAIN_ID"], os.environ["PYTHONUNBUFFERED"])']
    first = procs.start('node', show, env={'ROS_DOMAIN_ID': '42'})
    wait(lambda: first.poll() is not None, 30.0, 'the first run to exit')
    second = procs.start('node', show, env={'ROS_DOMAIN_ID': '43'}, log_name='node_2')
    wait(lambda: second.poll() is not None, 30.0, 'the second run to exit')
    procs.stop_all()
    assert procs.log(first) == 'base 42 1\n' and procs.log(second) == 'base 43 1\n'
    assert procs.procs['node'] is second and second.logs == [second.log_path, first.log_path]


def test_node_cmd_is_the_ros2_run_command_line_with_params_file_and_overrides():
    cmd = node_cmd('freejoint_sim', 'sim_node', 'config/sim.yaml', ['case:=vertical'])
    assert cmd[0].endswith('/freejoint_sim/lib/freejoint_sim/sim_node')
    assert cmd[1:] == ['--ros-args', '--params-file', 'config/sim.yaml', '-p', 'case:=vertical']


def test_thread_report_names_the_busy_and_the_sleeping_thread_of_a_process(tmp_path, wait):
    from freejoint_tools.harness import thread_report
    procs = Processes(str(tmp_path))
    busy = ('import threading, time\n'
            'def spin():\n'
            '    while True:\n'
            '        pass\n'
            'threading.Thread(target=spin, name="spinner", daemon=True).start()\n'
            'print("up", flush=True)\n'
            'time.sleep(60)\n')
    try:
        proc = procs.start('busy', [sys.executable, '-c', busy])
        wait(lambda: 'up' in procs.log('busy'), 30.0, 'the process to start')
        report = thread_report(proc.pid, 0.5)
    finally:
        procs.stop_all()
    lines = report.splitlines()
    assert lines[0].startswith('threads of %d over 0.5 s' % proc.pid)
    rows = {int(line.split()[0]): line.split() for line in lines[1:3]}
    # Python names the thread 'spinner' in its own name only: the kernel's is the
    # process's. The main thread sleeps (S, no CPU); the other spins (R: running or
    # runnable, with CPU time; how much of the 0.5 s depends on the machine's load).
    main, other = rows[proc.pid], next(r for t, r in rows.items() if t != proc.pid)
    assert main[2] == 'S' and float(main[5]) < 0.1, report
    assert other[2] == 'R' and float(other[5]) > float(main[5]), report
    assert main[3] == other[3] == 'OTHER/0'


def test_a_claimed_ros_domain_is_not_given_again_until_its_holder_dies(tmp_path, wait):
    # Two runs that prefer the same domain (two test runs' workers whose draws coincide):
    # the second gets the next free one, wrapping at the range's end; a holder killed
    # (SIGKILL, no clean-up of its own) gives its domain back.
    locks = str(tmp_path / 'locks')
    procs = Processes(str(tmp_path))
    try:
        holders = [procs.start('holder%d' % i, [sys.executable, '-c', CLAIMER, locks, 'hold'])
                   for i in range(2)]
        wait(lambda: all(procs.log(h) for h in holders), 30.0, 'both claims')
        assert sorted(int(procs.log(h)) for h in holders) == [5, 6]
        wrapped = procs.start('wrapped', [sys.executable, '-c', CLAIMER, locks])
        wait(lambda: wrapped.poll() is not None, 30.0, 'the wrapped claim')
        assert wrapped.returncode == 0 and int(procs.log(wrapped)) == 1
        os.killpg(holders[0].pid, signal.SIGKILL)
        holders[0].wait(30.0)
        again = procs.start('again', [sys.executable, '-c', CLAIMER, locks])
        wait(lambda: again.poll() is not None, 30.0, 'the claim after the kill')
        assert again.returncode == 0
        assert int(procs.log(again)) == int(procs.log(holders[0]))
    finally:
        procs.stop_all()
