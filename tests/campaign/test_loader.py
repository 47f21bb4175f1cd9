"""Campaign files: every problem with its line, values and designs expanded as written."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.corpus import campaign_file

from bagfault.campaign.loader import load_campaign
from bagfault.campaign.plan import make_plan, points
from bagfault.errors import CampaignError

BIAS = 'faults.bias.config.angular_velocity_z_bias'


def problems(path: Path) -> list[str]:
    with pytest.raises(CampaignError) as caught:
        load_campaign(path)
    return str(caught.value).splitlines()


def test_every_problem_is_named_with_its_line(corpus: Path) -> None:
    path = campaign_file(corpus, f"""\
        campaign: broken
        scenario: drift.yaml
        bags: [bags/*.mcap]
        sweep:
          faults.nope.config.x: [1]
          {BIAS}: {{range: [0, 1, 0]}}
          faults.bias.config.drop_probability: [0.5, 7]
        seeds: [-1]
        design: {{random: {{samples: 0}}}}
        keep: some
        mode: live
        speed: 3
    """)
    lines = problems(path)
    name = str(path)
    assert lines == [
        f'{name}:6:55: sweep.{BIAS}.range: step must be above 0 and give at most 100000 values',
        f'{name}:8:8: seeds: seeds are integers from 0 to 2^64 - 1',
        f'{name}:9:18: design.random: needs samples (1 to 100000) and an integer seed',
        f"{name}:10:7: keep: 'some' is not all, failed or none",
        f"{name}:11:7: mode: 'live' is not run or test",
        f"{name}:12:8: speed: unknown key 'speed' (did you mean 'seeds'? known: bags, campaign, design, keep, mode, scenario, search, "
        'seeds, sweep, timeout)',
    ]  # in file order; the swept paths are checked against the scenario once the file itself is sound: nope is not named


def test_swept_paths_and_values_are_checked_against_the_scenario(corpus: Path) -> None:
    path = campaign_file(corpus, f"""\
        campaign: paths
        scenario: drift.yaml
        bags: [bags/*.mcap]
        sweep:
          faults.nope.config.x: [1]
          faults.bias.config.drop_probability: [0.5, 7]
        search: {{parameter: {BIAS}, low: 0, high: 1, tolerance: 0.1, until: {{assertion: detected}}}}
        mode: test
    """)
    assert problems(path) == [
        f"{path}:5:25: sweep.faults.nope.config.x: no fault 'nope' (there are: bias)",
        f'{path}:6:40: sweep.faults.bias.config.drop_probability: 7 makes the scenario invalid: 7 is above the '
        'maximum 1.0',
        f"{path}:7:117: search.until.assertion: no assertion 'detected' in the scenario (there are: drift_detected)",
        f'{path}:8:7: mode: test needs a system_under_test section in the scenario',
    ]


def test_ranges_and_the_random_design(corpus: Path) -> None:
    path = campaign_file(corpus, f"""\
        campaign: ranges
        scenario: drift.yaml
        bags: [bags/a.mcap, bags/*.mcap]
        sweep:
          {BIAS}: {{range: [0.0, 0.5, 0.1]}}
          faults.bias.start: {{range: [1, 4]}}
        seeds: {{range: [0, 10, 5]}}
        design: {{random: {{samples: 7, seed: 3}}}}
    """)
    campaign = load_campaign(path)
    assert campaign.sweep == {BIAS: [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], 'faults.bias.start': [1, 2, 3]}
    assert campaign.seeds == [0, 5]
    chosen = points(campaign)
    grid = [{BIAS: b, 'faults.bias.start': s} for b in campaign.sweep[BIAS] for s in (1, 2, 3)]
    assert len(chosen) == 7 and all(p in grid for p in chosen)
    assert chosen == [p for p in grid if p in chosen]  # in grid order
    import random
    assert chosen == [grid[i] for i in sorted(random.Random(3).sample(range(18), 7))]  # the draw over grid indices
    assert points(load_campaign(path)) == chosen  # the design seed fixes the draw
    plan = make_plan(campaign)
    assert [b.name for b in plan.bags] == ['a.mcap', 'b.mcap']  # a bag named twice runs once
    assert len(plan.jobs) == 2 * 7 * 2 and len({j.key for j in plan.jobs}) == 28


def test_a_glob_that_finds_nothing_is_named(corpus: Path) -> None:
    path = campaign_file(corpus, """\
        campaign: empty
        scenario: drift.yaml
        bags: [fleet/*.mcap]
    """)
    with pytest.raises(CampaignError, match=r"bags: 'fleet/\*.mcap' matches no file or folder"):
        make_plan(load_campaign(path))


def test_the_progress_line_counts_jobs_and_estimates_what_is_left(monkeypatch: pytest.MonkeyPatch) -> None:
    import io

    from bagfault import progress

    now = [100.0]
    monkeypatch.setattr(progress.time, 'monotonic', lambda: now[0])
    stream = io.StringIO()
    bar = progress.JobProgress(stream=stream, enabled=True)
    bar.add(10, 2)  # 2 of 10 already stored
    now[0] = 130.0
    for status in ('passed', 'failed', 'error'):
        bar.finished(status)
    # 3 jobs ran in 30 s: the 5 left take 50 s
    assert bar.line() == '[############............] 5/10 jobs  1 passed  1 failed  1 error ETA 00:50'
    assert stream.getvalue().endswith(bar.line() + '\x1b[K')


def test_a_sweep_too_large_is_refused_before_anything_is_expanded(tmp_path: Path) -> None:
    """Two ranges of 1000 values make a million jobs: said at once, never expanded (it used to hang)."""
    import time

    from bagfault.campaign.loader import load_campaign
    from bagfault.campaign.plan import make_plan
    from bagfault.errors import CampaignError

    (tmp_path / 'bag.mcap').write_bytes(b'')
    (tmp_path / 's.yaml').write_text('injector: {id: i, type: imu, input_topic: /imu, output_topic: /imu}\n'
                                     'faults:\n  - {id: f, injector_id: i, start: 1.0, duration: 1.0, '
                                     'config: {angular_velocity_z_bias: 0.1}}\n')
    (tmp_path / 'c.yaml').write_text('campaign: huge\nscenario: s.yaml\nbags: [bag.mcap]\nsweep:\n'
                                     '  faults.f.config.angular_velocity_z_bias: {range: [0.0, 1.0, 0.001]}\n'
                                     '  faults.f.start: {range: [1.0, 2.0, 0.001]}\n')
    began = time.monotonic()
    campaign = load_campaign(tmp_path / 'c.yaml')
    with pytest.raises(CampaignError, match=r'makes 1,00[0-9],[0-9]{3} jobs \(1 bags x 100[01] '):
        make_plan(campaign)
    assert time.monotonic() - began < 10
    sampled = load_campaign(tmp_path / 'c.yaml')
    sampled.design, sampled.samples, sampled.design_seed = 'random', 5, 3
    plan = make_plan(sampled)  # a random design draws points of the grid without building it
    assert len(plan.jobs) == 5 and len({tuple(j.values.values()) for j in plan.jobs}) == 5


def test_a_campaign_without_a_name_is_named_after_its_file(corpus: Path) -> None:
    path = campaign_file(corpus, """\
        scenario: drift.yaml
        bags: [bags/a.mcap]
    """, name='nightly_drift.yaml')
    campaign = load_campaign(path)
    assert campaign.name == 'nightly_drift' and [Path(b).name for b in campaign.bags] == ['a.mcap']
