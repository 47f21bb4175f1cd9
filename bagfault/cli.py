"""Command line: argument parsing only; the work happens in bagfault.api."""

from __future__ import annotations

import argparse
import contextlib
import errno
import gc
import os
import signal
import sys
import time
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault import __version__, api, settings
from bagfault.errors import BagfaultError, LatencyError, UsageError, interrupt_inside
from bagfault.log import console
from bagfault.progress import ExploreProgress, JobProgress, ProgressBar

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

EXIT_OK, EXIT_FAILED, EXIT_ERROR = 0, 1, 2
INTERRUPTED: list[str] = []  # how the command was stopped, once a signal stopped it (bagfault.__main__ reads it)
EARLIER: list[Path] = []  # files published before this command began (an earlier `main` in this process)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        print(f'bagfault: error: {message}', file=sys.stderr)
        raise SystemExit(EXIT_ERROR)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog='bagfault', description='Record-and-replay fault injection for ROS 2.')
    parser.add_argument('--version', action='version', version=f'bagfault {__version__}')
    parser.add_argument('--debug', action='store_true', help='show tracebacks')
    sub = parser.add_subparsers(dest='command', required=True, parser_class=_Parser)

    run = sub.add_parser('run', help='inject faults into bags, write an output MCAP')
    run.add_argument('scenario', type=Path)
    run.add_argument('inputs', type=Path, nargs='+', metavar='INPUT')
    run.add_argument('-o', '--output', type=output_file, required=True)
    run.add_argument('--seed', type=int, default=None)
    run.add_argument('--activate', action='append', default=[], metavar='FAULT[@START[+DURATION]]',
                     help='activate a fault offline (seconds from bag time zero); repeatable')
    run.add_argument('--start', type=float, default=0.0, metavar='SECONDS',
                     help='bag time zero is this many seconds after the first message')
    run.add_argument('--compression', choices=['none', 'lz4', 'zstd'], default='zstd')
    run.add_argument('--compression-level', type=int, default=None, metavar='N',
                     help="level of the chunks bagfault writes (zstd -7..22, lz4 0..16; default: the MCAP C++ "
                          "writer's, zstd 1 and lz4 0; copied chunks keep theirs)")
    _salvage_option(run)
    run.add_argument('--no-chunk-copy', action='store_true',
                     help='decompress and rewrite every chunk (the reference path; default: chunks of a single '
                          'MCAP input that no fault, assertion or report touches are copied as they are)')
    run.add_argument('--verify', action='store_true',
                     help='also decompress, CRC-check and count every copied chunk, on a second thread (copied '
                          'chunks are otherwise checked against their indexes only)')
    _report_options(run)

    check = sub.add_parser('check', help="evaluate a scenario's assertions on an existing recording")
    check.add_argument('scenario', type=Path)
    check.add_argument('recording', type=Path, metavar='RECORDED.mcap')
    check.add_argument('--start', type=float, default=0.0, metavar='SECONDS',
                       help='bag time zero is this many seconds after the first message')
    _salvage_option(check)
    _report_options(check)

    validate = sub.add_parser('validate', help='check scenario files, report every problem')
    validate.add_argument('scenarios', type=Path, nargs='+', metavar='SCENARIO')
    _strict_option(validate)

    schema = sub.add_parser('schema', help='every key of scenario and campaign files, of each injector and '
                                           'assertion type; --json-schema for editors')
    schema.add_argument('type', nargs='?', metavar='TYPE', help='one injector type (default: everything)')
    schema.add_argument('--json', action='store_true', help='injector types as JSON')
    schema.add_argument('--json-schema', choices=('scenario', 'campaign'), default=None,
                        help='a JSON Schema of scenario or campaign files (for the YAML language server)')

    info = sub.add_parser('info', help='what a bag holds')
    info.add_argument('inputs', type=Path, nargs='+', metavar='BAG')

    latency = sub.add_parser('latency', help='path latency of a CARET architecture file on bags',
                             usage='bagfault latency ARCH.yaml BAG... [--path NAME] [--json F] [--html F]\n'
                                   '       bagfault latency validate ARCH.yaml')
    latency.add_argument('items', nargs='+', metavar='ARG', help='ARCH.yaml BAG..., or validate ARCH.yaml')
    latency.add_argument('--path', metavar='NAME', help='only this named path')
    latency.add_argument('--json', type=output_file, metavar='F')
    latency.add_argument('--html', type=output_file, metavar='F')
    _force_option(latency)
    latency.add_argument('--stamp-origin', action='store_true',
                         help="measure from the first message's header.stamp instead of its receive time")

    proxy = sub.add_parser('proxy', help="run the scenario's injectors on live ROS 2 topics (rclpy)",
                           usage='bagfault proxy SCENARIO [--record OUT.mcap] [--seed N] [--use-sim-time] [reports] '
                                 '[--ros-args -r __node:=NAME -r __ns:=/NS -r FROM:=TO -p FAULT.active:=true ...]')
    proxy.add_argument('scenario', type=Path)
    proxy.add_argument('--record', type=output_file, metavar='OUT.mcap', help='record raw and faulty topics and events')
    proxy.add_argument('--seed', type=int, default=None)
    proxy.add_argument('--use-sim-time', action='store_true', help='follow /clock (scheduler starts with it)')
    proxy.add_argument('--foxglove', nargs='?', const='', default=None, metavar='HOST:PORT',
                       help='a Foxglove WebSocket view: raw and faulty topics, events, faults as parameters, reload')
    _report_options(proxy)

    play = sub.add_parser('play', help="publish a bag on its topics, through a scenario's faults",
                          usage='bagfault play [SCENARIO.yaml] INPUT... [--rate R] [--clock] [--loop] '
                                '[--record OUT.mcap]')
    play.add_argument('items', type=Path, nargs='+', metavar='[SCENARIO] INPUT',
                      help='an optional scenario file (.yaml) followed by bags')
    play.add_argument('--rate', type=float, default=1.0, help='playback speed factor (default 1.0)')
    play.add_argument('--clock', type=float, nargs='?', const=100.0, default=None, metavar='HZ',
                      help='publish /clock with the bag time (at HZ while waiting, default 100)')
    play.add_argument('--loop', action='store_true', help='start again at the end, until Ctrl-C')
    play.add_argument('--record', type=output_file, metavar='OUT.mcap', help='record what was published and the events')
    play.add_argument('--seed', type=int, default=None)
    play.add_argument('--delay', type=float, default=0.5, metavar='SECONDS',
                      help='wait before the first message so subscribers can connect (default 0.5), then until '
                           'every subscriber the graph knows is matched (5 s at most)')
    play.add_argument('--wait-for', action='append', default=[], metavar='TOPIC',
                      help="wait (30 s at most) until TOPIC has a subscriber ('all': every topic played); repeatable")
    play.add_argument('--remap', action='append', default=[], metavar='/FROM:=/TO', help='publish FROM as TO')
    play.add_argument('--topics', nargs='+', default=[], metavar='TOPIC', help='play only these topics')
    play.add_argument('--foxglove', nargs='?', const='', default=None, metavar='HOST:PORT',
                      help='show the play in Foxglove (WebSocket, default 127.0.0.1:8765): topics, events, the faults '
                           'as parameters, playback controls; needs no ROS')
    play.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                      help="skip the bag's first S seconds (still judged: faults and assertions keep bag time)")
    _report_options(play)

    record = sub.add_parser('record', help='record live topics into an MCAP',
                            usage='bagfault record (TOPIC... | --all) -o OUT.mcap [--duration S]')
    record.add_argument('topics', nargs='*', metavar='TOPIC')
    record.add_argument('--all', action='store_true', help='every topic, including ones that appear later')
    record.add_argument('-o', '--output', type=output_file, required=True)
    _force_option(record)
    record.add_argument('--duration', type=float, default=None, metavar='S', help='stop after S seconds')
    record.add_argument('--use-sim-time', action='store_true', help='stamp messages with /clock time')

    test = sub.add_parser('test', help='closed loop: start the system under test, play the faulty bag into it, '
                                       'record and judge it',
                          usage='bagfault test SCENARIO [BAG...] [-o OUT.mcap] [--rate R] [--repeat N] '
                                '[--keep-logs DIR] [reports] [system options]')
    test.add_argument('scenario', type=Path)
    test.add_argument('inputs', type=Path, nargs='*', metavar='BAG', help="bags (default: the scenario's `bags`)")
    test.add_argument('-o', '--output', type=output_file, metavar='OUT.mcap',
                      help='one recording on bag time: played streams, events, what the system published')
    test.add_argument('--rate', type=float, default=1.0, help='playback speed factor (default 1.0)')
    test.add_argument('--repeat', type=int, default=1, metavar='N', help='run N times; pass rates per assertion')
    test.add_argument('--keep-logs', type=Path, metavar='DIR', help="keep the system's stdout and stderr here")
    test.add_argument('--seed', type=int, default=None)
    test.add_argument('--foxglove', nargs='?', const='', default=None, metavar='HOST:PORT',
                      help='a Foxglove WebSocket view of the loop (read-only)')
    system = test.add_argument_group('system under test (each replaces the key of `system_under_test:`)')
    system.add_argument('--command', dest='command_line', metavar='CMD', help='command line of the system')
    system.add_argument('--shell', action='store_true', default=None, help='run the command in /bin/sh')
    system.add_argument('--env', action='append', default=[], metavar='NAME=VALUE', help='repeatable')
    system.add_argument('--cwd', metavar='DIR')
    system.add_argument('--ready', action='append', default=[], metavar='SPEC',
                        help='publisher:/t, message:/t, subscribes:played|/a,/b, service:/s or delay:S, '
                             'each optionally @TIMEOUT; repeatable')
    system.add_argument('--record-topic', action='append', default=[], metavar='TOPIC',
                        help='a topic of the system to record (default: all it publishes); repeatable')
    system.add_argument('--stop-timeout', type=float, metavar='S', help='seconds between SIGINT, SIGTERM, SIGKILL')
    system.add_argument('--tail', type=float, metavar='S', help='bag seconds recorded after the last message')
    system.add_argument('--no-sim-time', action='store_true', help='do not pass use_sim_time:=true')
    _report_options(test)

    campaign = sub.add_parser('campaign', help='sweep a scenario over bags, fault parameters and seeds',
                              usage='bagfault campaign FILE -o DIR [--workers N] [--ray [ADDRESS]] [--resume] '
                                    '[--dry-run]')
    campaign.add_argument('campaign', type=Path, metavar='FILE')
    campaign.add_argument('-o', '--output-dir', metavar='DIR',
                          help='results.parquet, results.csv, campaign.json, report.html, jobs/, outputs/')
    _force_option(campaign)
    campaign.add_argument('--workers', type=int, default=None, metavar='N',
                          help='jobs at a time (default: one per core; with --ray: all the cluster takes)')
    campaign.add_argument('--ray', nargs='?', const='', default=None, metavar='ADDRESS',
                          help='run the jobs as Ray tasks: on a local Ray instance, or on the cluster at ADDRESS')
    campaign.add_argument('--resume', action='store_true',
                          help='keep the results already in DIR; run only what is missing or changed')
    campaign.add_argument('--dry-run', action='store_true', help='print the plan and its size, run nothing')

    explore = sub.add_parser('explore', help='search a fault space for failures, shrink each to its minimal cause',
                             usage='bagfault explore SPACE.yaml [BAG...] -o DIR [--budget N] [--seed N] '
                                   '[--workers K] [--engine local|ray] [--rate R] [--resume]')
    explore.add_argument('scenario', type=Path, metavar='SPACE.yaml',
                         help='a scenario with an explore: section (the candidate faults and their dimensions)')
    explore.add_argument('inputs', nargs='*', type=Path, metavar='BAG', help="default: the scenario's `bags:`")
    explore.add_argument('-o', '--output-dir', type=Path, metavar='DIR', required=True,
                         help='explore.json, report.html, runs.jsonl, failures/')
    explore.add_argument('--budget', type=int, metavar='N', help="runs in all (default: the space's `budget`)")
    explore.add_argument('--seed', type=int, metavar='N', help="the search's and every run's seed (default: the "
                                                               "scenario's)")
    explore.add_argument('--workers', type=int, metavar='K', help='runs at a time (default: one per core)')
    explore.add_argument('--engine', choices=('local', 'ray'), default='local',
                         help='a local pool of processes, or Ray tasks')
    explore.add_argument('--ray-address', metavar='ADDRESS', default='',
                         help='with --engine ray: the cluster (default: a local Ray instance)')
    explore.add_argument('--rate', type=float, default=1.0, metavar='R', help='closed loop: play at R x bag time')
    explore.add_argument('--resume', action='store_true', help='continue the exploration in DIR where it stopped')
    explore.add_argument('--save-failures', type=Path, metavar='DIR',
                         help='also write each minimal scenario as DIR/test_<name>.bagfault.yaml, a regression '
                              'suite the pytest plugin runs')
    _force_option(explore)

    recover = sub.add_parser('recover', help='make a recording cut short by a kill a valid MCAP again')
    recover.add_argument('recording', type=Path, metavar='FILE',
                         help='the partial file (.NAME.*.partial), or the name that was requested')
    recover.add_argument('-o', '--output', type=output_file, default=None,
                         help='default: the name that was requested')
    _force_option(recover)

    demo = sub.add_parser('demo', help='run the embedded demo bag and scenario')
    demo.add_argument('-o', '--output-dir', type=Path, default=Path('bagfault_demo'), metavar='DIR')

    return parser


def output_file(text: str) -> Path:
    """An output file name: one that names a folder (`out/`) is refused, not turned into a file `out`."""
    if not text or text.endswith(('/', os.sep)) or text in ('.', '..'):
        raise argparse.ArgumentTypeError(f'{text!r} names a folder; give a file name')
    return Path(text)


def _force_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--force', action='store_true',
                        help='replace existing output files that bagfault did not write (never an input)')


def _report_options(parser: argparse.ArgumentParser) -> None:
    _strict_option(parser)
    _force_option(parser)
    parser.add_argument('--report', type=output_file, metavar='R.md', help='markdown report')
    parser.add_argument('--json', type=output_file, metavar='R.json',
                        help='machine-readable report (docs/reference/report.md)')
    parser.add_argument('--junit', type=output_file, metavar='R.xml',
                        help="JUnit XML, one testcase per assertion (valid under Jenkins' junit-10 schema)")
    parser.add_argument('--junit-file-line', action='store_true',
                        help="also put the scenario's file and line on each testcase, which GitHub's and GitLab's "
                             "readers link (Jenkins' junit-10 schema refuses them)")
    parser.add_argument('--html', type=output_file, metavar='R.html', help='self-contained HTML report with plots')


def _salvage_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--salvage', action='store_true',
                        help='on corruption the file format detects (CRCs, record lengths), copy what can be read '
                             'and list what could not, instead of stopping')
    parser.add_argument('--msg-path', type=Path, action='append', default=[], metavar='DIR',
                        help='a folder of <package>/msg/<Name>.msg or .idl definitions for types the bag does not '
                             'carry; repeatable')


def _strict_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--strict', action='store_true',
                        help='treat scenario warnings (what ros2_fault_injection accepts but ignores) as errors')


def _reports(args: argparse.Namespace) -> api.ReportPaths:
    return api.ReportPaths(markdown=args.report, json=args.json, junit=args.junit, html=args.html,
                           junit_file_line=args.junit_file_line, force=args.force)


def _finish(result: api.RunResult) -> int:
    """The terminal summary and the exit code: the end of every command that runs a scenario."""
    api.print_summary(result)
    return EXIT_FAILED if result.failed else EXIT_OK


def _cmd_run(args: argparse.Namespace) -> int:
    bar = ProgressBar()
    try:
        result = api.run(
            args.scenario, args.inputs, args.output, seed=args.seed, activate=args.activate,
            start_offset=args.start, compression=args.compression, compression_level=args.compression_level,
            progress=bar, salvage=args.salvage, msg_paths=args.msg_path, chunk_copy=not args.no_chunk_copy,
            force=args.force, verify=args.verify, strict=args.strict, reports=_reports(args),
        )
    finally:
        bar.close()
    return _finish(result)


def _cmd_check(args: argparse.Namespace) -> int:
    bar = ProgressBar()
    try:
        result = api.check(args.scenario, args.recording, start_offset=args.start, progress=bar,
                           salvage=args.salvage, msg_paths=args.msg_path, strict=args.strict, reports=_reports(args))
    finally:
        bar.close()
    return _finish(result)


def _cmd_proxy(args: argparse.Namespace) -> int:
    return _finish(api.proxy(args.scenario, record=args.record, seed=args.seed, use_sim_time=args.use_sim_time,
                             ros_args=args.ros_args, foxglove=args.foxglove, force=args.force, strict=args.strict,
                             reports=_reports(args)))


def _cmd_play(args: argparse.Namespace) -> int:
    items = list(args.items)
    scenario_path = None
    if items[0].suffix in ('.yaml', '.yml') and items[0].is_file():
        scenario_path = items.pop(0)
    if not items:
        raise UsageError('play: give at least one bag after the scenario')
    return _finish(api.play(scenario_path, items, rate=args.rate, clock=args.clock is not None, loop=args.loop,
                            record=args.record, seed=args.seed, delay=args.delay, wait_for=args.wait_for,
                            remap=args.remap, topics=args.topics, start_offset=args.start_offset,
                            clock_hz=args.clock if args.clock is not None else 100.0, ros_args=args.ros_args,
                            foxglove=args.foxglove, force=args.force, strict=args.strict, reports=_reports(args)))


def _cmd_record(args: argparse.Namespace) -> int:
    result = api.record(args.topics, args.output, every=args.all, duration=args.duration,
                        use_sim_time=args.use_sim_time, ros_args=args.ros_args, force=args.force)
    for topic, count in sorted(result.counts.items()):
        print(f'  {count:>9}  {topic}' + (f'  (lost {result.lost[topic]})' if result.lost.get(topic) else ''))
    for topic in result.missing:
        print(f'note: {topic} never appeared; nothing recorded for it')
    for topic, msgtype in sorted(result.skipped.items()):
        print(f'note: {topic} ({msgtype}) not recorded: no Python bindings for the type here')
    print(f'recorded {sum(result.counts.values())} messages on {len(result.counts)} topics to {result.output}'
          + (f' (stopped by {result.reason})' if result.reason else ''))
    if result.lost:
        lost = ', '.join(f'{count} of {topic}' for topic, count in result.lost.items())
        print(f'bagfault: warning: the recording lost {sum(result.lost.values())} messages ({lost}): the '
              'recorder fell behind or the network dropped them', file=sys.stderr)
    return EXIT_OK


def _system_overrides(args: argparse.Namespace) -> dict[str, object]:
    """`system_under_test` keys given on the command line, in their YAML form (`--ready` as written: the API
    reads it)."""
    given = [('command', args.command_line), ('shell', True if args.shell else None),
             ('env', _env_pairs(args.env) if args.env else None), ('cwd', args.cwd),
             ('ready', list(args.ready) if args.ready else None),
             ('record', list(args.record_topic) if args.record_topic else None),
             ('stop_timeout', args.stop_timeout), ('tail', args.tail),
             ('use_sim_time', False if args.no_sim_time else None)]
    return {key: value for key, value in given if value is not None}


def _env_pairs(items: list[str]) -> dict[str, str]:
    """`--env NAME=VALUE` options as a mapping."""
    pairs = [item.partition('=') for item in items]
    bad = [item for item, (name, sep, _) in zip(items, pairs, strict=True) if not (name and sep)]
    if bad:
        raise UsageError(f'--env {bad[0]}: must be NAME=VALUE')
    return {name: value for name, _, value in pairs}


def _cmd_test(args: argparse.Namespace) -> int:
    return _finish(api.test(args.scenario, args.inputs, args.output, system=_system_overrides(args), seed=args.seed,
                            rate=args.rate, repeat=args.repeat, keep_logs=args.keep_logs, foxglove=args.foxglove,
                            force=args.force, strict=args.strict, reports=_reports(args)))


def _cmd_campaign(args: argparse.Namespace) -> int:
    if args.dry_run:
        print(api.campaign_plan(args.campaign))
        return EXIT_OK
    if args.output_dir is None:
        raise UsageError('campaign: -o DIR is required (or --dry-run)')
    try:
        result = api.campaign(args.campaign, args.output_dir, workers=args.workers, ray=args.ray, resume=args.resume,
                              progress=JobProgress(), force=args.force)
    except KeyboardInterrupt:
        INTERRUPTED.append('SIGINT')
        print(f'bagfault: interrupted; finished jobs are kept in {_under(args.output_dir, "jobs")}, --resume '
              'continues', file=sys.stderr)
        return EXIT_ERROR
    _print_campaign(result, args.output_dir)
    return EXIT_FAILED if result.failed else EXIT_OK


def _print_campaign(result: Any, output_dir: Path | str) -> None:  # an api.campaign result
    """A campaign's counts, breaking points, notes and where its tables and report are."""
    c = result.counts
    campaign = result.plan.campaign
    search = f', {len(result.table.rows) - len(result.table.sweep_rows())} search jobs' \
        if campaign.search is not None else ''
    print(f'{campaign.name}: {sum(c.values())} jobs: {c["passed"]} passed, {c["failed"]} failed, {c["error"]} error'
          f'{search} ({result.ran} run now, on {result.engine})')
    for point in result.breaking_points:
        where = f'holds from {point.value:g}' if point.value is not None else \
            'never holds' if point.below is not None else 'undecided'
        print(f'breaking point {point.parameter} on {point.bag.name}: {where} ({point.note})')
    for note in result.notes:
        print(f'note: {note}')
    parquet = [_under(output_dir, 'results.parquet')] if result.parquet else []
    print(f'results   {", ".join([*parquet, _under(output_dir, "results.csv")])}')
    print(f'report    {_under(output_dir, "report.html")}')


def _cmd_explore(args: argparse.Namespace) -> int:
    try:
        result = api.explore(args.scenario, args.inputs, args.output_dir, budget=args.budget, seed=args.seed,
                             workers=args.workers, ray=args.ray_address if args.engine == 'ray' else None,
                             rate=args.rate, resume=args.resume, force=args.force,
                             save_failures=args.save_failures, progress=ExploreProgress())
    except KeyboardInterrupt:
        INTERRUPTED.append('SIGINT')
        print(f'bagfault: interrupted; the runs made are kept in {args.output_dir / "runs.jsonl"}, --resume '
              'continues', file=sys.stderr)
        return EXIT_ERROR
    shrunk = [f for f in result.failures if f.state == 'shrunk']
    print(f'{args.scenario}: {len(result.runs)} of {result.budget} runs ({result.ran} now, on {result.engine}): '
          f'{len(shrunk)} failure{"s" if len(shrunk) != 1 else ""} found')
    for failure in result.failures:
        _print_failure(failure, args.output_dir)
    for path in result.saved:
        print(f'saved     {path}')
    for warning in result.warnings:
        print(f'warning: {warning}', file=sys.stderr)
    print(f'results   {_under(args.output_dir, "explore.json")}')
    print(f'report    {_under(args.output_dir, "report.html")}')
    return EXIT_FAILED if result.failed else EXIT_OK


def _print_failure(failure: Any, output_dir: Path) -> None:  # one of an api.explore result's failures
    """One failure an exploration found: what fails, its minimal cause, how it was found and its replay."""
    if failure.minimal is None:
        print(f'  {failure.name}: {failure.note}')
        return
    replay = failure.replay.status if failure.replay is not None else 'not replayed'
    print(f'  {failure.name}: fails {", ".join(sorted(failure.assertions))}')
    print(f'      minimal: {failure.minimal.describe()}')
    print(f'      found at run {failure.found_at_run}, shrunk in {failure.shrink_runs} runs, replay {replay}: '
          f'{_under(output_dir, f"failures/{failure.name}.min.yaml")}')


def _under(folder: Path | str, name: str) -> str:
    """A file of a campaign's folder or bucket prefix, as the user would name it."""
    return f'{folder.rstrip("/")}/{name}' if isinstance(folder, str) else str(folder / name)


def _cmd_recover(args: argparse.Namespace) -> int:
    done = api.recover(args.recording, args.output, force=args.force)
    state = 'complete (nothing was lost)' if done.complete else f'cut short ({done.stopped})'
    print(f'{done.source}: {state}')
    print(f'recovered {done.messages} messages on {done.channels} channels into {done.output}')
    return EXIT_OK


def _cmd_demo(args: argparse.Namespace) -> int:
    code = _finish(api.demo(args.output_dir))
    print(f'report    {args.output_dir / "demo_report.md"}, {args.output_dir / "demo_report.html"}')
    return code


def _cmd_validate(args: argparse.Namespace) -> int:
    for scenario in api.validate(args.scenarios, strict=args.strict):
        for warning in scenario.warnings:
            print(f'warning: {warning}', file=sys.stderr)
        space = scenario.explore
        explore = '' if space is None else (f', an explore space of {len(space.faults)} candidates and '
                                            f'{sum(len(f.dimensions) for f in space.faults)} dimensions')
        print(f'{scenario.source}: ok ({len(scenario.injectors)} injectors, {len(scenario.faults)} faults, '
              f'{len(scenario.assertions)} assertions{explore})')
    return EXIT_OK


def _cmd_schema(args: argparse.Namespace) -> int:
    print(api.schema(args.type, as_json=args.json, json_schema_of=args.json_schema))
    return EXIT_OK


def _cmd_latency(args: argparse.Namespace) -> int:
    items = args.items
    if items[0] == 'validate':
        if len(items) != 2:
            raise LatencyError('usage: bagfault latency validate ARCH.yaml')
        outcome = api.latency(items[1])
    elif len(items) < 2:
        raise LatencyError('usage: bagfault latency ARCH.yaml BAG... (or: bagfault latency validate ARCH.yaml)')
    else:
        outcome = api.latency(items[0], items[1:], path=args.path, stamp_origin=args.stamp_origin, json=args.json,
                              html=args.html, force=args.force)
    for warning in outcome.warnings:
        print(f'warning: {warning}', file=sys.stderr)
    print(outcome.text)
    return EXIT_OK if outcome.usable else EXIT_ERROR


def _cmd_info(args: argparse.Namespace) -> int:
    print(api.info(args.inputs))
    return EXIT_OK


COMMANDS = {
    'run': _cmd_run,
    'check': _cmd_check,
    'validate': _cmd_validate,
    'schema': _cmd_schema,
    'info': _cmd_info,
    'demo': _cmd_demo,
    'proxy': _cmd_proxy,
    'play': _cmd_play,
    'record': _cmd_record,
    'test': _cmd_test,
    'recover': _cmd_recover,
    'campaign': _cmd_campaign,
    'explore': _cmd_explore,
    'latency': _cmd_latency,
}


ROS_COMMANDS = ('proxy', 'play', 'record')  # commands that make a node: they take --ros-args


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `bagfault` command: exit 0 passed, 1 an assertion failed, 2 could not run.

    A terminal that cannot take the messages (stdout or stderr on a full device) is exit 2 too: a verdict
    whose reasons were lost is not a verdict.
    """
    if argv is None:  # the process's command (not a call from Python): before numpy loads
        settings.one_blas_thread()
    try:
        with _terminating_signals():  # SIGTERM and SIGHUP as Ctrl-C from the first instant, parsing included
            code = _main(argv)
        sys.stdout.flush()
        sys.stderr.flush()
        if argv is None:  # the process's command, about to exit: the interpreter's last collection skips what is
            gc.freeze()   # left (0.023 s of a `run`'s 0.07 s teardown; everything is still closed as usual)
    except KeyboardInterrupt as exc:  # before the command's own handling (arguments, imports)
        with contextlib.suppress(OSError):
            print(f'bagfault: {_stopped_by(exc)}; {_written()}', file=sys.stderr)
        return EXIT_ERROR
    except RuntimeError as exc:  # one that carries a signal (see interrupt_inside); any other is raised on
        interrupt = interrupt_inside(exc)
        if interrupt is None:
            raise
        with contextlib.suppress(OSError):
            print(f'bagfault: {_stopped_by(interrupt)}; {_written()}', file=sys.stderr)
        return EXIT_ERROR
    except OSError:  # stderr itself failed while saying why
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stderr.fileno())
        return EXIT_ERROR
    return code


def _main(argv: Sequence[str] | None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    ros_args: list[str] = []
    if '--ros-args' in words:  # as `ros2 run` and launch pass them: everything after it is for ROS
        at = words.index('--ros-args')
        words, ros_args = words[:at], [w for w in words[at + 1:] if w not in ('--ros-args', '--')]
    try:
        os.getcwd()
    except OSError:
        print('bagfault: error: the current directory no longer exists (deleted?); cd somewhere that does',
              file=sys.stderr)
        return EXIT_ERROR
    args = _parser().parse_args(words)
    args.ros_args = ros_args
    console(debug=args.debug)
    if ros_args and args.command not in ROS_COMMANDS:
        print(f'bagfault: error: --ros-args: only {", ".join(ROS_COMMANDS)} make a ROS node', file=sys.stderr)
        return EXIT_ERROR
    began = time.monotonic()
    EARLIER[:] = api.published()
    try:
        with _terminating_signals():
            settings.check()  # a bad environment variable is one line before anything runs
            return COMMANDS[args.command](args)
    except BagfaultError as exc:
        if args.debug:
            traceback.print_exc()
        for line in str(exc).splitlines() or [type(exc).__name__]:
            print(f'bagfault: error: {line}', file=sys.stderr)
        for warning in getattr(exc, 'warnings', ()):  # a scenario's warnings, with its errors
            print(f'bagfault: warning: {warning}', file=sys.stderr)
        _junit_error(args, str(exc).splitlines()[0] if str(exc) else type(exc).__name__, began)
        tail = getattr(exc, 'tail', None)
        if tail:
            print('bagfault: the last lines of the system under test:', file=sys.stderr)
            for line in tail:
                print(f'  | {line}', file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt as exc:
        if args.debug:
            traceback.print_exc()
        print(f'bagfault: {_stopped_by(exc)}; {_written()}', file=sys.stderr)
        _junit_error(args, 'interrupted', began)
        return EXIT_ERROR
    except BrokenPipeError:  # `bagfault schema | head`: the reader left, nothing is wrong
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except OSError as exc:  # the machine, not bagfault: a full device, a vanished file, a terminal that failed
        if args.debug:
            traceback.print_exc()
        where = f'{exc.filename}: ' if exc.filename else 'the terminal (stdout): ' if exc.errno in TERMINAL else ''
        if where.startswith('the terminal'):  # the summary was lost: nothing more goes to stdout
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        print(f'bagfault: error: {where}{exc.strerror or exc}; {_written()}', file=sys.stderr)
        _junit_error(args, f'{where}{exc.strerror or exc}', began)
        return EXIT_ERROR
    except Exception as exc:  # noqa: BLE001 - a bug must still end with the documented exit code
        if args.debug:
            traceback.print_exc()
        interrupt = interrupt_inside(exc)
        if interrupt is not None:  # Python wrapped it (a signal while a class was made: __set_name__)
            print(f'bagfault: {_stopped_by(interrupt)}; {_written()}', file=sys.stderr)
            _junit_error(args, 'interrupted', began)
            return EXIT_ERROR
        print(f'bagfault: internal error: {type(exc).__name__}: {exc} (a bug in bagfault; --debug shows where)',
              file=sys.stderr)
        _junit_error(args, f'internal error: {type(exc).__name__}: {exc}', began)
        return EXIT_ERROR


TERMINAL = (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EFBIG)


def _stopped_by(exc: KeyboardInterrupt) -> str:
    """'interrupted' (Ctrl-C) or 'stopped by SIGTERM' (the name _terminating_signals gives)."""
    name = str(exc)
    INTERRUPTED.append(name or 'SIGINT')
    return f'stopped by {name}' if name.startswith('SIG') else 'interrupted'


def _written() -> str:
    """What the command had put under its final names before it stopped: true whenever it stops."""
    written = api.published()[len(EARLIER):]
    if not written:
        return 'nothing was written under the requested names'
    return 'written before that: ' + ', '.join(str(p) for p in written)


def _junit_error(args: argparse.Namespace, reason: str, began: float) -> None:
    """Exit 2 with --junit: the file says why (CI shows the reason, not "no report"), unless that path is itself
    the problem or names anything else given on the command line."""
    path = getattr(args, 'junit', None)
    if not isinstance(path, Path):
        return
    named: list[tuple[str, Path]] = []
    for key, value in vars(args).items():
        values = value if isinstance(value, list) else [value]
        named += [(key, v) for v in values if isinstance(v, Path) and key != 'junit']
    api.junit_error(path, str(getattr(args, 'scenario', None) or args.command), reason, time.monotonic() - began,
                    extended=getattr(args, 'junit_file_line', False), protected=named)


@contextlib.contextmanager
def _terminating_signals() -> Iterator[None]:
    """SIGTERM and SIGHUP end the command as Ctrl-C does: outputs are abandoned, temporary files removed.

    Live commands replace these while they run: there a signal is a clean stop.
    """
    def interrupt(number: int, _frame: object) -> None:
        raise KeyboardInterrupt(signal.Signals(number).name)

    previous = {number: signal.signal(number, interrupt) for number in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


if __name__ == '__main__':
    sys.exit(main())
