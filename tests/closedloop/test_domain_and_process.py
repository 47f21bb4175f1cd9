"""Domain leases and the system's process group: isolation between runs, and nothing left running."""

from __future__ import annotations

import contextlib
import itertools
import os
import random
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
from support.helpers import claim_port_base
from support.loop import running_with

from bagfault.closedloop.domain import DomainLease
from bagfault.closedloop.process import ProcessStat, SystemProcess, describe_exit, family, processes
from bagfault.errors import ClosedLoopError


@pytest.fixture
def locks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Lock files and claim ports of this test alone (a second suite beside it runs the same ids)."""
    folder = tmp_path / 'locks'
    monkeypatch.setenv('BAGFAULT_DOMAIN_LOCKS', str(folder))
    monkeypatch.setenv('BAGFAULT_DOMAIN_PORT_BASE', str(claim_port_base(random.Random())))
    monkeypatch.setenv('ROS_DOMAIN_ID', '0')
    return folder


def test_leases_and_ros_domain_coordinator_never_share_a_domain(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """colcon's isolated tests and launch_testing claim a domain with domain_coordinator (the
    ros-jazzy-domain-coordinator wheel): the TCP port 32768 + id, bound. A lease skips theirs, theirs skips ours."""
    domain_coordinator = pytest.importorskip('domain_coordinator')
    monkeypatch.setenv('BAGFAULT_DOMAIN_LOCKS', str(tmp_path / 'locks'))  # our locks are free: only ports count
    monkeypatch.delenv('BAGFAULT_DOMAIN_PORT_BASE', raising=False)
    monkeypatch.setenv('ROS_DOMAIN_ID', '0')
    with domain_coordinator.domain_id(selector=itertools.cycle(range(30, 101)).__next__) as theirs, \
            pytest.raises(ClosedLoopError) as refused:
        DomainLease(theirs, theirs)
    assert f'no free ROS domain id between {theirs} and {theirs}' in str(refused.value)
    with DomainLease() as mine:
        first_choice = itertools.chain([mine.domain], itertools.cycle(range(30, 101)))
        with domain_coordinator.domain_id(selector=first_choice.__next__) as theirs:
            assert theirs != mine.domain


def test_leases_are_exclusive_and_given_back(locks: Path) -> None:
    first, second = DomainLease(40, 41), DomainLease(40, 41)
    assert {first.domain, second.domain} == {40, 41}
    with pytest.raises(ClosedLoopError, match='no free ROS domain id between 40 and 41'):
        DomainLease(40, 41)
    taken = first.domain
    first.release()
    with DomainLease(40, 41) as third:
        assert third.domain == taken
    second.release()


def test_a_lease_held_by_another_process_is_skipped_and_freed_when_it_dies(locks: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, '-c', 'import sys, time\nfrom bagfault.closedloop.domain import DomainLease\n'
                               'lease = DomainLease(50, 51)\nprint(lease.domain, flush=True)\ntime.sleep(60)'],
        stdout=subprocess.PIPE, text=True, env=os.environ)
    try:
        held = int(holder.stdout.readline())  # type: ignore[union-attr]
        with DomainLease(50, 51) as mine:
            assert mine.domain == ({50, 51} - {held}).pop()
    finally:
        holder.kill()
        holder.wait()
    with DomainLease(50, 51) as a, DomainLease(50, 51) as b:  # the kernel dropped the dead holder's lock
        assert {a.domain, b.domain} == {50, 51}


def test_a_lease_leaves_no_lock_file_and_removes_those_of_a_killed_run(locks: Path) -> None:
    """A released lease removes its lock file; a run killed with SIGKILL leaves its file unlocked, and the next
    lease (of any id) removes it. A file another live process holds stays."""
    with DomainLease(40, 41) as lease:
        assert sorted(p.name for p in locks.iterdir()) == [f'{lease.domain}.lock']
    assert list(locks.iterdir()) == []
    killed = subprocess.Popen(
        [sys.executable, '-c', 'import os, time\nfrom bagfault.closedloop.domain import DomainLease\n'
                               'lease = DomainLease(44, 44)\nprint(lease.domain, flush=True)\ntime.sleep(60)'],
        stdout=subprocess.PIPE, text=True, env=os.environ)
    holder = subprocess.Popen(
        [sys.executable, '-c', 'import time\nfrom bagfault.closedloop.domain import DomainLease\n'
                               'lease = DomainLease(45, 45)\nprint(lease.domain, flush=True)\ntime.sleep(60)'],
        stdout=subprocess.PIPE, text=True, env=os.environ)
    try:
        assert int(killed.stdout.readline()) == 44 and int(holder.stdout.readline()) == 45  # type: ignore[union-attr]
        killed.kill()
        killed.wait()
        assert sorted(p.name for p in locks.iterdir()) == ['44.lock', '45.lock']  # the killed run's is left
        with DomainLease(40, 41):
            assert sorted(p.name for p in locks.iterdir()) in (['40.lock', '45.lock'], ['41.lock', '45.lock'])
        assert sorted(p.name for p in locks.iterdir()) == ['45.lock']  # held by a live process: kept
    finally:
        holder.kill()
        holder.wait()


def test_leases_that_remove_their_files_stay_exclusive_under_contention(locks: Path) -> None:
    """Eight processes lease and release one of two ids as fast as they can for 2 s while each records when it
    held which: no two ever held the same id at once, though each lease removes its lock file on release (each
    waits 2 ms between opening a lock file and locking it, so that holders remove files in that moment), and no
    lock file is left."""
    script = (
        'import fcntl, json, sys, time\nlocking = fcntl.flock\n'
        'fcntl.flock = lambda handle, op: (time.sleep(0.002) if op & fcntl.LOCK_EX else None, locking(handle, op))[1]\n'
        'from bagfault.closedloop.domain import DomainLease\nfrom bagfault.errors import '
        'ClosedLoopError\nspans = []\nend = time.monotonic() + 2\nwhile time.monotonic() < end:\n'
        '    try:\n        lease = DomainLease(40, 41)\n    except ClosedLoopError:\n        continue\n'
        '    began = time.monotonic()\n    time.sleep(0.001)\n    spans.append((lease.domain, began, '
        'time.monotonic()))\n    lease.release()\nprint(json.dumps(spans))\n')
    workers = [subprocess.Popen([sys.executable, '-c', script], stdout=subprocess.PIPE, text=True, env=os.environ)
               for _ in range(8)]
    import json

    spans = [span for worker in workers for span in json.loads(worker.communicate(timeout=60)[0])]
    assert len(spans) > 50  # the contention happened
    for domain in (40, 41):
        held = sorted((b, e) for d, b, e in spans if d == domain)
        overlaps = [(a, b) for a, b in itertools.pairwise(held) if b[0] < a[1]]
        assert overlaps == [], f'domain {domain} held twice at once: {overlaps[:3]}'
    assert list(locks.iterdir()) == []


def test_the_current_domain_is_never_leased(locks: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv('ROS_DOMAIN_ID', '60')
    with DomainLease(60, 61) as lease:
        assert lease.domain == 61


SLEEP = f"{sys.executable} -c 'import time; time.sleep(300)'"  # a long sleeper that takes extra arguments
# the same, saying on stderr when Python runs (a SIGINT before that ends it without a KeyboardInterrupt)
READY_SLEEP = (f"{sys.executable} -c 'import sys, time; print(\"sleeping\", file=sys.stderr, flush=True); "
               "time.sleep(300)'")


def start(tmp_path: Path, script: str, token: str) -> SystemProcess:
    return SystemProcess([f'{script} # {token}'], env=dict(os.environ), cwd=tmp_path, shell=True, logs=tmp_path)


def wait_for(predicate: object, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():  # type: ignore[operator]
        assert time.monotonic() < deadline, 'condition not reached'
        time.sleep(0.05)


def test_sigint_ends_a_well_behaved_group(tmp_path: Path) -> None:
    token = uuid.uuid4().hex
    process = start(tmp_path, f'echo started; {READY_SLEEP} {token}-a & {READY_SLEEP} {token}-b; wait', token)
    wait_for(lambda: len(running_with(token)) >= 3 and process.tail().count('sleeping') == 2)
    assert process.stop(timeout=5.0) == 'SIGINT'
    assert [name for name, _ in process.sent] == ['SIGINT']  # the one signal sent, nothing more
    assert running_with(token) == []
    assert process.leftovers() == set()
    tail = process.tail()
    assert tail[0] == 'started'  # stdout first, then stderr: the sleepers' KeyboardInterrupt
    assert tail[-1] == 'KeyboardInterrupt'


def test_a_system_started_while_sigint_is_ignored_still_stops_on_sigint(tmp_path: Path) -> None:
    """bagfault run as a shell's background job (or under nohup) has SIGINT ignored, and a child inherits that:
    the system must still get SIGINT's default action, or every stop would wait for SIGTERM."""
    import signal

    token = uuid.uuid4().hex
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        process = start(tmp_path, f'exec {READY_SLEEP} {token}', token)
    finally:
        signal.signal(signal.SIGINT, previous)
    wait_for(lambda: process.tail().count('sleeping') == 1)
    assert process.stop(timeout=5.0) == 'SIGINT'
    assert running_with(token) == [] and process.tail()[-1] == 'KeyboardInterrupt'


def test_escalation_to_sigterm_and_sigkill(tmp_path: Path) -> None:
    token = uuid.uuid4().hex
    process = start(tmp_path, f"trap '' INT; {SLEEP} {token} & wait; wait", token)
    wait_for(lambda: len(running_with(token)) >= 2)
    began = time.monotonic()
    assert process.stop(timeout=0.5) == 'SIGTERM'
    assert running_with(token) == []
    assert time.monotonic() - began < 5
    assert [name for name, _ in process.sent] == ['SIGINT', 'SIGTERM']  # SIGINT was trapped: both were sent
    assert 0.5 <= process.sent[1][1] < 2.0  # SIGTERM after the 0.5 s timeout

    stubborn = tmp_path / 'stubborn.py'
    stubborn.write_text('import signal, sys, time\nfor s in (signal.SIGINT, signal.SIGTERM):\n'
                        '    signal.signal(s, signal.SIG_IGN)\nprint("ignoring", flush=True)\ntime.sleep(300)\n')
    token = uuid.uuid4().hex
    process = start(tmp_path, f'exec {sys.executable} {stubborn} {token}', token)
    wait_for(lambda: 'ignoring' in process.stdout_path.read_text())
    assert process.stop(timeout=0.3) == 'SIGKILL'
    assert process.returncode == -9
    assert running_with(token) == []


def test_a_child_that_left_the_group_is_stopped_too(tmp_path: Path) -> None:
    token = uuid.uuid4().hex
    process = start(tmp_path, f'setsid {SLEEP} {token}-escaped & {SLEEP} {token}', token)
    wait_for(lambda: len(running_with(token)) >= 3)
    process.watch()  # the run loop looks at the family while the system runs
    process.stop(timeout=2.0)
    assert running_with(token) == []


def test_a_pid_the_kernel_gave_to_another_program_is_never_signalled(tmp_path: Path) -> None:
    """A process of the system seen during the run ended and its pid went to an unrelated program (pids wrap at
    32768 here): that program has another start time, is not counted as the system's, and is left running."""
    bystander = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(300)'])
    try:
        token = uuid.uuid4().hex
        process = start(tmp_path, f'{READY_SLEEP} {token}', token)
        wait_for(lambda: 'sleeping' in process.stderr_path.read_text())
        began = next(p.start for p in processes() if p.pid == bystander.pid)
        process._known[bystander.pid] = began - 1     # what the run saw: an earlier process with this pid
        assert bystander.pid not in process.leftovers()
        assert process.stop(timeout=2.0) == 'SIGINT'
        assert bystander.poll() is None and running_with(token) == []
        process._known[bystander.pid] = began         # had it been the system's own (daemonised) child
        assert process.leftovers() == {bystander.pid}
    finally:
        bystander.kill()
        bystander.wait()


def test_a_group_id_taken_by_a_new_program_is_not_the_systems(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tables written by hand. The system's leader 100 (started at tick 7) led group 100 with child 101; once
    the whole group ended, the kernel may give 100 to a new program that leads a group 100 of its own: another
    start time, and neither it nor its group is the system's. Descendants of a known process stay the system's."""
    from bagfault.closedloop import process as module

    def table(*rows: tuple[int, int, int, int]) -> None:
        monkeypatch.setattr(module, 'processes', lambda: [ProcessStat(pid, ppid, pgid, 'S', start)
                                                          for pid, ppid, pgid, start in rows])

    table((100, 1, 100, 7), (101, 100, 100, 9), (300, 101, 300, 12))   # 300: a child that left the group
    assert family(100, {}) == {100: 7, 101: 9, 300: 12}
    table((100, 1, 100, 50), (102, 100, 100, 51))                      # pid 100 is someone else's now
    assert family(100, {100: 7, 101: 9}) == {}
    table((102, 1, 100, 51))                                           # its leader gone, its member stays
    assert family(100, {100: 7}) == {102: 51}   # no live pid 100 to tell: the group is taken as the system's


def test_a_system_that_exits_by_itself(tmp_path: Path) -> None:
    process = start(tmp_path, 'echo one; echo two >&2; exit 3', 'x')
    wait_for(lambda: not process.alive())
    assert process.returncode == 3
    assert process.stop(timeout=1.0) == 'exited'
    assert process.tail() == ['one', 'two']


def test_a_command_that_cannot_start(tmp_path: Path) -> None:
    with pytest.raises(ClosedLoopError, match='cannot start /nonexistent/robot_stack --fast: No such file'):
        SystemProcess(['/nonexistent/robot_stack', '--fast'], env=dict(os.environ), cwd=None, shell=False,
                      logs=tmp_path)


def test_exit_descriptions() -> None:
    assert describe_exit(3) == 'code 3'
    assert describe_exit(-11) == 'signal SIGSEGV'
    assert describe_exit(None) == 'no exit code'


def test_process_table_matches_ps() -> None:
    ours = next(p for p in processes() if p.pid == os.getpid())
    ps = subprocess.run(['ps', '-o', 'ppid=,pgid=,etimes=', '-p', str(os.getpid())], capture_output=True,
                        text=True, check=False)
    uptime = float(Path('/proc/uptime').read_text().split()[0])
    if ps.returncode != 0:
        pytest.skip('ps not available')
    ppid, pgid, elapsed = (int(v) for v in ps.stdout.split())
    assert [ours.ppid, ours.pgid] == [ppid, pgid]
    assert abs(uptime - ours.start / os.sysconf('SC_CLK_TCK') - elapsed) < 2.0   # start: ticks since boot


DAEMON = (f"{sys.executable} -c 'import os, sys, time\n"
          "if os.fork(): sys.exit(0)\n"
          "os.setsid()\n"
          "if os.fork(): sys.exit(0)\n"
          "time.sleep(300)'")  # the classic double fork: a new session, its parent gone before anyone looks


def daemon_of(process: SystemProcess, token: str) -> int | None:
    """The daemon: a process of the token in a session other than the system's, and not that session's leader
    (the leader is the middle process of the double fork, which exits at once)."""
    for pid in running_with(f'{token}-daemon'):
        with contextlib.suppress(ProcessLookupError):
            session = os.getsid(pid)
            if pid != process.pid and session not in (process.pid, os.getsid(0), pid):
                return pid
    return None


def test_a_daemon_that_double_forked_out_of_the_session_is_stopped_too(tmp_path: Path) -> None:
    """Never seen as a descendant (its parents exit at once, it is re-parented and leads a session of its own):
    it still carries the run's mark in its environment."""
    token = uuid.uuid4().hex
    process = start(tmp_path, f'{DAEMON} {token}-daemon; {SLEEP} {token}', token)
    wait_for(lambda: daemon_of(process, token) is not None)
    daemon = daemon_of(process, token)
    assert daemon is not None and os.getsid(daemon) != process.pid  # it left the system's session

    def parent(pid: int) -> int:  # (the field after the command's closing parenthesis, then the state)
        return int(Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[1])

    # once its parent has exited (on a busy machine a moment after the daemon exists), it is re-parented
    wait_for(lambda: parent(daemon) not in family(process.pid, {}))
    assert daemon not in family(process.pid, {})  # and no walk of the system's descendants finds it
    assert daemon in process.pids()  # so the isolation check does not take it for a stranger
    process.stop(timeout=2.0)
    assert running_with(token) == []


def test_the_watchdog_ends_a_daemon_when_bagfault_dies(tmp_path: Path) -> None:
    """bagfault SIGKILLed: the watchdog's pipe closes without `done`; it ends the session and the marked daemon."""
    token = uuid.uuid4().hex
    process = start(tmp_path, f'{DAEMON} {token}-daemon; {SLEEP} {token}', token)
    wait_for(lambda: daemon_of(process, token) is not None)
    watchdog = process._watchdog
    assert watchdog is not None and watchdog.stdin is not None
    watchdog.stdin.close()  # as the kernel closes it when bagfault is killed
    wait_for(lambda: running_with(token) == [], timeout=10.0)
    watchdog.wait(timeout=5)
    process.popen.wait(timeout=5)


def test_scratch_folders_of_dead_runs_are_swept_and_live_ones_kept(tmp_path: Path) -> None:
    """A run holds a lock on its scratch folder's `.owner` while it lives; the next run removes the folders whose
    lock is free (a run killed with its watchdog), never a live run's, one being made, or anything else."""
    from bagfault.closedloop.watchdog import hold_scratch, sweep_scratch

    live, dead, making, other = (tmp_path / n for n in ('bagfault-test-live', 'bagfault-test-dead',
                                                         'bagfault-test-making', 'notes'))
    for folder in (live, dead, making, other):
        folder.mkdir()
        (folder / 'system.stdout.log').write_text('log\n')
    (dead / '.owner').write_text('')
    (other / '.owner').write_text('')
    holder = subprocess.Popen([sys.executable, '-c', 'import sys, time\nfrom bagfault.closedloop.watchdog import '
                               f'hold_scratch\nhold_scratch({str(live)!r})\nprint("held", flush=True)\ntime.sleep(60)'],
                              stdout=subprocess.PIPE, text=True, env=os.environ)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == 'held'
        os.close(hold_scratch(str(tmp_path / 'bagfault-test-dead')))  # held and let go: as a run that ended
        assert sweep_scratch(str(tmp_path)) == ['bagfault-test-dead']
        assert sorted(p.name for p in tmp_path.iterdir()) == ['bagfault-test-live', 'bagfault-test-making', 'notes']
    finally:
        holder.kill()
        holder.wait()
    assert sweep_scratch(str(tmp_path)) == ['bagfault-test-live']  # its run is gone now


def test_a_process_started_again_and_the_system_s_own_processes_all_append_to_its_logs(tmp_path: Path) -> None:
    """The system's processes and one started again after them write the same log files: every line of each is
    kept, whoever writes last (a writer that does not append writes at its own offset, over the lines the
    restarted process appended: a restarted controller's 'controller up' was lost so under load)."""
    from bagfault.closedloop.process import Launch

    token = uuid.uuid4().hex
    marker = tmp_path / 'go'
    script = (f"{sys.executable} -c 'import pathlib, sys, time; print(\"first\", file=sys.stderr, flush=True); "
              f"[time.sleep(0.02) for _ in iter(lambda: pathlib.Path(\"{marker}\").exists(), True)]; "
              "print(\"third, written by the first process after the restarted one wrote\", file=sys.stderr, "
              "flush=True); time.sleep(300)'")
    process = start(tmp_path, script, token)
    try:
        wait_for(lambda: 'first' in process.tail())
        again = process.start_again(Launch([sys.executable, '-c', 'import sys; print("second", file=sys.stderr)'],
                                           dict(os.environ), str(tmp_path), 0))
        again.wait(timeout=30)
        marker.touch()
        wait_for(lambda: 'third' in (tmp_path / 'system.stderr.log').read_text())
        lines = (tmp_path / 'system.stderr.log').read_text().splitlines()
        assert lines == ['first', 'second', 'third, written by the first process after the restarted one wrote']
    finally:
        process.stop(timeout=5.0)
