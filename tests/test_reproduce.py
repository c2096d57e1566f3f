"""``shacc reproduce --quick``: every output exists and holds what the issue names."""

from __future__ import annotations

import contextlib
import io
import json
import re

import pytest

from sweeps.app.cli import main
from sweeps.app.reproduce_cmd import CATEGORIES, README_BEGIN, README_END


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    readme = tmp_path_factory.mktemp("readme") / "README.md"  # not in --out: not its file
    readme.write_text(f"# x\n\n{README_BEGIN}\nold\n{README_END}\n\ntail\n")
    # A small search (the optimized mode's defaults are measured in benchmarks).
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["reproduce", "--quick", "--random-scenes", "2", "--field-grid", "6",
                     "--workers", "1", "--out", str(out), "--readme", str(readme),
                     "--set", "optimize_population=8", "--set", "optimize_generations=3",
                     "--set", "optimize_starts=16"]) == 0
    PROGRESS.append(err.getvalue())
    return out, readme


PROGRESS: list[str] = []  # the quick run's stderr


def test_every_program_is_a_progress_line(quick_run):
    """Compiling is most of the command's time: each program prepared says so when it
    starts and how long its trace and compilation took, named after its stage."""
    lines = PROGRESS[0].splitlines()
    done = [ln for ln in lines if re.search(r"program \([\d,]+ rollouts of work\): "
                                           r"(traced|read back) in [\d.]+ s, compiled in "
                                           r"[\d.]+ s$", ln)]
    for stage in ("robustness: ", "intent: ", "success fields: "):
        assert any(f"]   {stage}evaluate program" in ln for ln in done), stage
    assert any("search program" in ln for ln in done)
    started = [ln for ln in lines if ln.endswith(": preparing")]
    assert len(started) == len(done) >= 5
    # Intent inference needs only the precomputed scenes: it begins beside the main
    # evaluation, not after it.
    begun = next(i for i, ln in enumerate(lines) if "] intent inference: " in ln)
    evaluated = next(i for i, ln in enumerate(lines) if re.search(r"\d+ rollouts in ", ln))
    assert begun < evaluated


def test_summary_keys(quick_run):
    out, _ = quick_run
    s = json.loads((out / "summary.json").read_text())
    for k in ("C", "d", "h"):
        assert set(s["correlation"][k]) >= {"rho", "ci"}
    assert s["correlation"]["C"]["rho"] < 0
    assert list(s["categories"]) == list(CATEGORIES)
    for c in CATEGORIES:
        cat = s["categories"][c]
        assert "n_scenes" in cat
        for mode in ("baseline", "shrinking", "shacc", "optimized"):
            assert set(cat[mode]) == {"u_scene", "delta_R", "C_final"}
            assert set(cat[mode]["u_scene"]) >= {"mean", "ci"}
        # The search is never worse than Shrinking on its own starts.
        assert cat["search_gain"]["mean"] is None or cat["search_gain"]["mean"] >= 0
        assert set(cat["optimized_gain"]) >= {"mean", "ci"}
    assert s["categories"]["all"]["n_scenes"] == len(s["scenes"]) == 14
    scene = s["scenes"][0]
    assert set(scene) >= {"name", "set", "category", "C_init", "C_final", "d", "h",
                          "baseline", "shrinking", "shacc", "optimized", "C_optimized",
                          "search_objective"}
    assert set(scene["shacc"]) == {"u_scene", "delta_R_mean"}
    assert s["settings"]["software"]["jax"] and s["settings"]["bootstrap_resamples"] == 200
    assert s["settings"]["preset"] == "paper" and "random-paper-" in s["scenes"][-1]["name"]
    # Every claim of the paper's Fig. 6 text, beside ours and a verdict by a stated rule.
    ids = [c["id"] for c in s["claims"]]
    assert {"rho_C", "u_cinit_pos", "dr_cinit_pos", "c_init_sparse", "u_sparse"} <= set(ids)
    for c in s["claims"]:
        assert c["holds"] in ("holds", "does not hold", "n/a") and c["paper"] and c["rule"]
    assert {"C_given_tasks", "tasks"} <= set(s["partial_correlation"])


def test_what_the_numbers_must_show(quick_run):
    out, _ = quick_run
    s = json.loads((out / "summary.json").read_text())
    cats = s["categories"]
    pos = cats["cinit_pos"]
    assert pos["shrinking"]["C_final"]["mean"] < pos["baseline"]["C_final"]["mean"]
    assert pos["shrinking"]["u_scene"]["mean"] > pos["baseline"]["u_scene"]["mean"]
    unc = cats["uncluttered"]
    assert unc["shrinking"]["u_scene"]["mean"] >= unc["baseline"]["u_scene"]["mean"]
    for c in CATEGORIES:
        assert cats[c]["shacc"]["u_scene"]["mean"] == cats[c]["shrinking"]["u_scene"]["mean"]
    assert cats["cluttered"]["shacc"]["delta_R"]["mean"] < \
        cats["cluttered"]["baseline"]["delta_R"]["mean"]


def test_report_figures_and_readme(quick_run):
    out, readme = quick_run
    report = (out / "report.md").read_text()
    assert "| C correlates negatively with baseline success | -0.53 [-0.72, -0.27] |" in report
    assert "partial correlation" in report
    assert "**(c) success rate u_scene**" in report
    assert "| category | n | baseline | shrinking | shacc | optimized |" in report
    assert "How far is Shrinking from the best sizes?" in report
    for name in ("fig6a_correlation", "fig6b_c_final", "fig6c_success", "fig6d_delta_r",
                 "fig7_success_fields"):
        png = out / f"{name}.png"
        assert png.stat().st_size > 5000
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = readme.read_text()
    assert "\nold\n" not in text and text.endswith("tail\n") and "Pearson" in text
    # The last two stages ran side by side: each within the block's wall time; intent
    # inference from the main evaluation's start to the block's end at most.
    t = json.loads((out / "summary.json").read_text())["timing_s"]
    stages = [t["robustness"], t["success_fields"]]
    assert min(stages) > 0 and max(stages) <= t["side_by_side"] <= t["total"]
    assert 0 < t["intent"] <= t["evaluate"] + t["statistics"] + t["side_by_side"]
    assert f"then side by side in {t['side_by_side']:.1f} s" in report


def test_robustness_section(quick_run):
    """Every user parameter at the perfect level and its quick level, in every mode, with
    scene-level CIs and paired differences to the baseline; the verdict follows from
    the rows by its rule; the report and the figure show them."""
    from sweeps.analysis import robustness

    out, _ = quick_run
    s = json.loads((out / "summary.json").read_text())
    section = s["robustness"]
    assert list(section) == list(robustness.QUICK_LEVELS)
    n_scenes = s["categories"]["all"]["n_scenes"]
    for param, entry in section.items():
        levels = [r["level"] for r in entry["rows"]]
        assert levels == [robustness.PERFECT[param], *robustness.QUICK_LEVELS[param]]
        for r in entry["rows"]:
            assert set(r["modes"]) == {"baseline", "shrinking", "shacc", "optimized"}
            assert r["modes"]["shacc"]["u_scene"]["n"] == n_scenes
            d = r["vs_baseline"]["shacc"]
            assert d["mean"] == pytest.approx(r["modes"]["shacc"]["u_scene"]["mean"]
                                              - r["modes"]["baseline"]["u_scene"]["mean"])
        assert entry["verdict"]["shacc"] == robustness.verdict(entry["rows"], "shacc")
        assert entry["sentence"] in (out / "report.md").read_text()
    # The perfect row is the main evaluation's: its ShaCC success is the table's.
    assert section["user_tremor"]["rows"][0]["modes"]["shacc"]["u_scene"]["mean"] == \
        pytest.approx(s["categories"]["all"]["shacc"]["u_scene"]["mean"])
    # The wandering hand starts from white noise of the same size (not the perfect
    # user), and a wandering hand changes something.
    assert section["user_noise_tau"]["rows"][0]["modes"]["shacc"]["u_scene"]["mean"] != \
        pytest.approx(s["categories"]["all"]["shacc"]["u_scene"]["mean"])
    assert "at 0.0," in section["user_noise_tau"]["sentence"]
    noisy = section["user_noise_tau"]["rows"]
    assert any(noisy[0]["modes"][m]["u_scene"]["mean"] != noisy[1]["modes"][m]["u_scene"]["mean"]
               for m in ("baseline", "shacc"))
    assert (out / "robustness.png").stat().st_size > 10_000


def test_intent_section(quick_run):
    """The paper's open question on the random scenes: every user and intent mode with
    scene-level CIs; the perfect user's baseline and ShaCC are the main table's on the
    same scenes; the shares of time sum to one; one sentence per comparison, in the
    report, the README and the figure."""
    from sweeps.analysis import intent

    out, readme = quick_run
    s = json.loads((out / "summary.json").read_text())
    section = s["intent"]
    assert section["modes"] == list(intent.MODES) and list(section["users"]) == \
        list(intent.USERS)
    randoms = [sc for sc in s["scenes"] if sc["set"] == "random"]
    assert section["n_scenes"] == len(randoms) == 2
    perfect = section["users"]["the perfect user"]["modes"]
    for mode in ("baseline", "shacc"):
        want = sum(sc[mode]["u_scene"] for sc in randoms) / len(randoms)
        assert perfect[mode]["u_scene"]["mean"] == pytest.approx(want, abs=1e-6)
    for entry in section["users"].values():
        for e in entry["modes"].values():
            shares = [e["assist"][k]["mean"] for k in ("none", "scene", "correct", "wrong")]
            assert sum(shares) == pytest.approx(1.0, abs=1e-6)
        # The paper's modes never assist towards a task; ho always does before the end.
        assert entry["modes"]["baseline"]["assist"]["correct"]["mean"] == 0
        assert entry["modes"]["ho"]["assist"]["none"]["mean"] < 0.1
        # shacc, blend, ho against the baseline, shacc_ho against shacc and ho: success,
        # then delta_R.
        assert len(entry["sentences"]) == 10
        assert sum("delta_R" in line for line in entry["sentences"]) == 5
        for line in entry["sentences"]:
            assert line in (out / "report.md").read_text()
            assert line in readme.read_text()
    # A change of mind: assistance that infers the goal is wrong some of the time.
    mind = section["users"]["a change of mind in every approach"]["modes"]
    assert mind["ho"]["assist"]["wrong"]["mean"] > 0
    assert "## ShaCC and intent inference" in (out / "report.md").read_text()
    assert (out / "intent_assistance.png").stat().st_size > 5_000


def _row(level, diff, ci):
    return {"level": level, "vs_baseline": {"shacc": {"mean": diff, "ci": ci}}}


@pytest.mark.parametrize(("diffs", "expected"), [
    ([(0.3, [0.2, 0.4]), (0.28, [0.1, 0.4]), (0.25, [0.05, 0.4])], "holds"),
    ([(0.3, [0.2, 0.4]), (0.1, [0.02, 0.2])], "shrinks"),
    ([(0.3, [0.2, 0.4]), (0.25, [-0.05, 0.5])], "shrinks"),
    ([(0.3, [0.2, 0.4]), (-0.2, [-0.3, -0.1])], "reverses"),
    ([(0.0, [-0.1, 0.1]), (0.1, [0.05, 0.2])], "none"),
])
def test_verdict_rule(diffs, expected):
    from sweeps.analysis.robustness import verdict

    rows = [_row(i, d, ci) for i, (d, ci) in enumerate(diffs)]
    assert verdict(rows, "shacc") == expected


def test_the_last_stages_run_side_by_side_and_say_the_first_error(monkeypatch):
    """The robustness, intent and field stages run at once (each is mostly compiling):
    two stages that each wait for the other finish only if they overlap; each gets an
    equal share of the memory budget; a failed stage's error is raised after every
    other stage has ended, the first in the stages' order."""
    import threading
    import time

    import shacc_jax
    from sweeps.app.reproduce_cmd import side_by_side

    monkeypatch.setenv("SHACC_MEMORY_BUDGET", "1000M")
    meet = threading.Barrier(2, timeout=30)
    budgets = []

    def meeting(name):
        def stage(budget_bytes):
            budgets.append(budget_bytes)
            meet.wait()  # BrokenBarrierError if the other never runs alongside
            return name
        return stage

    done = side_by_side({"a": meeting("a"), "b": meeting("b")})
    assert {k: v[0] for k, v in done.items()} == {"a": "a", "b": "b"}
    assert all(v[1] >= 0 for v in done.values())
    assert budgets == [shacc_jax.budget() // 2] * 2 == [500 * 2**20] * 2

    ended = []

    def slow(_):
        time.sleep(0.3)
        ended.append("slow")

    def fails(message):
        def stage(_):
            raise ValueError(message)
        return stage

    with pytest.raises(ValueError, match="first"):
        side_by_side({"slow": slow, "one": fails("first"), "two": fails("second")})
    assert ended == ["slow"]
