"""``tools/tuning_runs.py``: the tuning protocol's run list and its paired comparison."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def tool(load_tool):
    return load_tool("tuning_runs")


def _report(path: Path, bag: str, method: str, seed: int, mean: float) -> None:
    path.write_text(json.dumps({"bag": f"/somewhere/{bag}.mcap", "seed": seed,
                                "methods": {method: {"mean_mm": mean}}}))


def test_the_sets_are_the_documented_tuning_bags(tool, tmp_path):
    sets = tool.tuning_sets(tmp_path)
    running, guard = sets["running"], sets["guard"]
    assert [b.name for b in running] == [f"tune_02_03_s{s}" for s in range(25, 31)]
    assert all(b.silhouettes == "fg" and b.frames is None for b in running)
    assert running[0].bvh.exists()  # the runner ships with the tools
    assert {b.name for b in guard} == {"tune_13_29", "tune_02_05", "tune_01_01"}
    assert all(b.silhouettes == "gt" and b.frames == 60 and b.bvh.parent == tmp_path
               for b in guard)
    wide, distractors = sets["wide"], sets["distractors"]
    assert [b.seed for b in wide] == list(range(31, 57))
    assert not {b.name for b in wide} & {b.name for b in running}
    assert all(b.distractors and b.max_people == 2 and b.silhouettes == "fg"
               for b in distractors)
    assert distractors[0].name == "tune_02_03_s60_distractors"
    cmd = tool.eval_command(distractors[0], tmp_path / "d.mcap", "hpf-apo", 6, [],
                            tmp_path / "d.json")
    assert cmd[cmd.index("--max-people") + 1] == "2"
    assert "--max-people" not in tool.eval_command(running[0], tmp_path / "r.mcap", "hpf-apo",
                                                   6, [], tmp_path / "r.json")


def test_eval_command_and_resume(tool, tmp_path):
    guard = tool.tuning_sets(tmp_path)["guard"][0]
    cmd = tool.eval_command(guard, tmp_path / "g.mcap", "dd-hpf", 3, ["survival_rate=0.3"],
                            tmp_path / "out.json")
    joined = " ".join(cmd)
    for part in ("eval mocap", "--method dd-hpf", "--seed 3", "--threads 1",
                 "--silhouettes gt", "--frames 60", "--param survival_rate=0.3"):
        assert part in joined
    bags = tool.tuning_sets(tmp_path)["running"][:2]
    (tmp_path / tool.report_name(bags[0].name, "hpf-apo", 0)).write_text("{}")
    todo = tool.pending_runs(bags, ["hpf-apo"], [0, 1], tmp_path)
    assert [(b.name, m, s) for b, m, s in todo] == [
        (bags[0].name, "hpf-apo", 1), (bags[1].name, "hpf-apo", 0), (bags[1].name, "hpf-apo", 1)]


def test_paired_stats(tool):
    st = tool.paired_stats([(50.0, 47.0), (60.0, 58.0), (40.0, 41.0)])
    assert st["n"] == 3 and st["lower"] == 2
    assert st["base"] == pytest.approx(50.0) and st["cand"] == pytest.approx(146 / 3)
    diffs = [-3.0, -2.0, 1.0]
    mean = sum(diffs) / 3
    sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / 2)
    assert st["diff"] == pytest.approx(mean) and st["se"] == pytest.approx(sd / math.sqrt(3))
    assert math.isnan(tool.paired_stats([(1.0, 2.0)])["se"])
    assert tool.paired_stats([]) == {"n": 0}


def test_compare_pairs_by_bag_method_and_seed_and_applies_the_rule(tool, tmp_path, capsys):
    base, cand = tmp_path / "base", tmp_path / "cand"
    base.mkdir()
    cand.mkdir()
    for seed, (b, c) in enumerate([(60.0, 55.0), (58.0, 54.0)]):
        _report(base / f"x{seed}.json", "tune_02_03_s25", "hpf-apo", seed, b)
        _report(cand / f"y{seed}.json", "tune_02_03_s25", "hpf-apo", seed, c)
    _report(base / "g.json", "tune_13_29", "dd-hpf", 0, 50.0)
    _report(cand / "g.json", "tune_13_29", "dd-hpf", 0, 52.5)
    _report(cand / "only.json", "tune_02_03_s26", "hpf-apo", 0, 10.0)  # no partner: left out
    (cand / "broken.json").write_text("not json")

    def run(*extra):
        rc = tool.main(["--workdir", str(tmp_path), "--shared-bvh", str(tmp_path), "compare",
                        "base", "cand", *extra])
        return rc, capsys.readouterr().out

    rc, out = run("--rule", "3")
    assert rc == 0
    assert "running: 2 runs, 59.00 -> 54.50 mm, difference -4.50" in out
    assert "guard: 1 runs, 50.00 -> 52.50 mm, difference +2.50" in out
    assert "1 runs in only one of the two sets left out" in out
    assert "DOES NOT PASS" in out and "guard over +1 mm" in out
    rc, out = run("--rule", "3", "--guard-limit", "3")
    assert "PASSES" in out
    rc, out = run("--rule", "5", "--guard-limit", "3")
    assert "DOES NOT PASS: running mean does not drop by at least 5 mm" in out


def test_reports_made_with_other_settings_are_named(tool, tmp_path):
    from hmocap_ros.eval.mocap_eval import stored_params

    bags = tool.tuning_sets(tmp_path)["running"][:1]
    now = stored_params("hpf-apo")
    old = dict(now, survival_rate=0.5)
    for seed, params in ((0, now), (1, old)):
        (tmp_path / tool.report_name(bags[0].name, "hpf-apo", seed)).write_text(json.dumps(
            {"methods": {"hpf-apo": {"mean_mm": 50.0, "params": params}}}))
    lines = tool.settings_mismatches(bags, ["hpf-apo"], [0, 1, 2], tmp_path, [])
    assert len(lines) == 1 and lines[0].startswith(tool.report_name(bags[0].name, "hpf-apo", 1))
    assert f"survival_rate 0.5 -> {now['survival_rate']!r}" in lines[0]
    # asked for the old value, the other report is the odd one
    lines = tool.settings_mismatches(bags, ["hpf-apo"], [0, 1], tmp_path, ["survival_rate=0.5"])
    assert len(lines) == 1 and "_hpf-apo_0.json" in lines[0]
    # a report from before start_height_margin existed was made at its inert value (0)
    older = {k: v for k, v in now.items() if k != "start_height_margin"}
    (tmp_path / tool.report_name(bags[0].name, "hpf-apo", 2)).write_text(json.dumps(
        {"methods": {"hpf-apo": {"mean_mm": 50.0, "params": older}}}))
    assert tool.settings_mismatches(bags, ["hpf-apo"], [2], tmp_path,
                                    ["start_height_margin=0"]) == []
    lines = tool.settings_mismatches(bags, ["hpf-apo"], [2], tmp_path,
                                     ["start_height_margin=0.06"])
    assert len(lines) == 1 and "start_height_margin None -> 0.06" in lines[0]
