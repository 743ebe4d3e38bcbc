"""Every example of the documentation (README.md and the pages of docs/) runs as printed and says what it claims.

A Python block runs as it stands, except a fragment, which opens with ``# given:`` naming what the reader supplies
(it must compile). The walk-throughs' printed outputs are compared with what the commands print.
"""

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).parents[1]
PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)]
FRAGMENT = "# given:"


def _blocks(lang="python"):
    """``[(page, code)]`` of every ``lang`` block of every page, in page order."""
    return [(page, code) for page in PAGES for code in re.findall(rf"```{lang}\n(.*?)```", page.read_text(), re.S)]


def _run_block(marker):
    """Execute the first Python block of the documentation containing ``marker``; its namespace."""
    page, code = next((p, b) for p, b in _blocks() if marker in b)
    ns = {}
    exec(compile(code, str(page.relative_to(ROOT)), "exec"), ns)
    return ns


#: The blocks the tests below run with their own checks (a marker each); the generic test runs the others.
CHECKED = ("efficiency[2]", "DampedNavigator", "information_rank", 'write_psins("bench.imu"', 'write_csv("gnss.csv"',
           'method="kf")')


def test_documentation_has_its_examples():
    assert len(_blocks()) >= 9
    for marker in CHECKED:
        assert sum(marker in b for _, b in _blocks()) == 1, marker


@pytest.mark.parametrize("page, code", [pc for pc in _blocks() if not any(m in pc[1] for m in CHECKED)],
                         ids=lambda x: x.name if isinstance(x, Path) else "")
def test_every_other_example_runs(page, code, tmp_path, monkeypatch):
    compiled = compile(code, str(page), "exec")
    if code.startswith(FRAGMENT):
        return  # a fragment: the reader's names (it compiled)
    monkeypatch.chdir(tmp_path)
    exec(compiled, {})


def test_readme_example_is_near_optimal_as_it_says(capsys):
    """README's ten lines: kf's error about the limit scatters by the attainable bound (10 runs: an optimal
    estimator's RMS lies within 0.42-1.68 bounds at 99.8 %), and the bound is the 2.1 arcmin the README quotes."""
    ns = _run_block('method="kf")')
    fb = ns["fb"]
    _, bound = fb.metrics.attainable_bound(ns["spec"], 300.0, trajectory=ns["bench"])
    bound = bound[-1] / fb.units.ARCMIN
    assert bound[2] == pytest.approx(2.1, abs=0.05)
    rms = np.sqrt(((ns["phi"] - ns["limit"]) ** 2).mean(axis=0))
    assert 0.42 < rms[2] / bound[2] < 1.68
    assert np.all(rms[:2] < 3 * bound[:2])
    assert "error about the limit" in capsys.readouterr().out


def test_study_example_levels_on_the_limit(capsys):
    ns = _run_block("efficiency[2]")
    mean = ns["phi"].mean(axis=0)
    # level: accelerometer bias / g, up to the white noise averaged over 20 runs x 300 s (~0.001 arcmin)
    assert mean[:2] == pytest.approx(ns["limit"][:2], abs=0.01)
    assert "limit" in capsys.readouterr().out


def test_damping_page_example_runs(capsys):
    ns = _run_block("DampedNavigator")
    assert ns["phi"].shape == (2, 4000, 3)
    assert "q now" in capsys.readouterr().out


def test_rolling_page_example_runs_and_meets_its_bound(capsys):
    ns = _run_block("information_rank")
    assert "rank 45" in capsys.readouterr().out
    # the torquer errors within 3 of the filter's sigmas, and those within 2 of the information bound
    model = ns["model"]
    sig = model.to_customary(ns["res"].sigma[-1, :42])[model.KT]
    bound = model.to_customary(ns["bound"][:42])[model.KT]
    assert np.all(np.abs(ns["err"][model.KT]) < 3 * sig) and np.all(sig < 2 * bound)


def _shown(title):
    """The output the documentation prints under its ``$ fusionbench <title> ...`` line: (command, lines)."""
    block = next(b for p in PAGES for b in re.findall(r"```\n(\$ fusionbench .*?)```", p.read_text(), re.S)
                 if b.startswith(f"$ fusionbench {title}"))
    first, *rest = block.strip("\n").split("\n")
    return first[2:].split(), rest


_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def _same_numbers(shown, printed, rel=0.02):
    """The page's lines and the printed ones say the same words and, within ``rel``, the same numbers."""
    assert len(shown) == len(printed)
    for a, b in zip(shown, printed):
        assert _NUMBER.sub("#", a) == _NUMBER.sub("#", b), (a, b)
        for x, y in zip(_NUMBER.findall(a), _NUMBER.findall(b)):
            assert float(x) == pytest.approx(float(y), rel=rel, abs=1e-12), (a, b)


def test_sensor_page_identify_consistency_twin(tmp_path, monkeypatch):
    """The sensor page's walk-through on the file it makes: the printed outputs are what the commands print, the
    identified noise is the simulator's truth, and the twin runs on the identified spec."""
    import subprocess
    import sys

    from scipy.stats import chi2

    monkeypatch.chdir(tmp_path)
    _run_block('write_psins("bench.imu"')

    def run(args):
        r = subprocess.run([sys.executable, "-m", "fusionbench", *args[1:]], capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0, r.stderr
        return r.stdout.strip("\n").split("\n")

    cmd, shown = _shown("identify")
    printed = run(cmd)
    _same_numbers(shown, printed)
    from fusionbench.simulation.imu import load_spec
    from fusionbench.simulation.units import DEG_PER_SQRT_H, UG_PER_SQRT_HZ

    spec = load_spec("identified/imu_spec.toml")
    # the truth: 0.05 deg/sqrt(h) and 30 ug/sqrt(Hz) (an hour of 100 Hz pins N to about 0.2 %)
    assert np.array(spec.gyro.white) / DEG_PER_SQRT_H == pytest.approx([0.05] * 3, rel=0.01)
    assert np.array(spec.accel.white) / UG_PER_SQRT_HZ == pytest.approx([30.0] * 3, rel=0.01)

    cmd, shown = _shown("consistency")
    printed = run(cmd)
    _same_numbers(shown, printed)
    import json

    res = json.loads((tmp_path / "consistency" / "consistency.json").read_text())
    pairs = res["windows"] - 1
    lo, hi = (np.sqrt(chi2.ppf(q, pairs) / pairs) for q in (0.001, 0.999))
    assert lo < res["methods"]["kf"]["summary"]["rms_over_expected"]["U"] < hi

    cmd, shown = _shown("run twin")
    assert cmd[:3] == ["fusionbench", "run", "twin"] and "--imu" in cmd and "--site" in cmd
    small = cmd[1:] + ["--methods", "coarse-i0", "--runs", "1"]  # the same command, one method, one run
    run(["fusionbench", *small[:small.index("--out") + 1], "twin-small", *small[small.index("--out") + 2:]])
    m = json.loads((tmp_path / "twin-small" / "metrics.json").read_text())
    assert {c["lat_deg"] for c in m["conditions"].values()} == {34.2} and m["conditions"]["static-h0"]["imu"] == "bench"


def test_moving_page_walk_through(tmp_path, monkeypatch, capsys):
    """"Align a moving recording": the block writes the files, the command prints what the page shows, the answer
    is near the truth the block prints, and without the aiding, or to a method of fixed bases, it is refused."""
    from fusionbench.cli import main

    monkeypatch.chdir(tmp_path)
    ns = _run_block('write_csv("gnss.csv"')
    assert "the truth at 300 s: pitch 1.0000 deg, roll -2.0000 deg, heading 70.0000 deg" in capsys.readouterr().out
    cmd, shown = _shown("align drive.imu --method kf --aiding")
    assert main(cmd[1:]) == 0
    printed = capsys.readouterr().out.strip("\n").split("\n")
    _same_numbers(shown, printed)
    line = next(p for p in printed if p.startswith("pitch "))
    pitch, roll, heading = (float(x) for x in re.findall(r"-?\d+\.\d+", line))
    assert printed[-1] == "inside the method's claim"
    # within three of this drive's attainable bounds (about 1 arcmin of heading, 0.05 of level) of the truth
    assert abs(pitch - 1.0) * 60 < 0.2 and abs(roll + 2.0) * 60 < 0.2 and abs(heading - 70.0) * 60 < 3.0
    assert ns["car"].duration == 300.0
    for args in (cmd[1:cmd.index("--aiding")], cmd[1:3] + ["--method", "adrc"] + cmd[5:]):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and ("--aiding FILE" in err or "expected none or rows at rest" in err), err


def test_api_reference_lists_every_module():
    """docs/reference/index.md names every module of the four packages (autosummary documents those it names)."""
    page = (ROOT / "docs" / "reference" / "index.md").read_text()
    modules_part = page.split("\n## fusionbench: the API and the command line\n", 1)[1]
    listed = set(re.findall(r"^   ([a-z_][\w.]*)$", modules_part, re.M))
    modules = set()
    for package in ("fusionbench", "adrc", "baselines", "damping"):
        for path in (ROOT / package).rglob("*.py"):
            if path.name != "__main__.py" and not (path.stem.startswith("_") and path.stem != "__init__"):
                parts = path.relative_to(ROOT).with_suffix("").parts
                modules.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    assert len(modules) > 100 and not sorted(modules - listed) and not sorted(listed - modules)


def test_api_reference_names_every_top_level_name():
    """The reference's first table is ``fusionbench.API``: every ``fb.<name>`` where it is documented."""
    import fusionbench as fb

    page = (ROOT / "docs" / "reference" / "index.md").read_text()
    table = page.split("## `import fusionbench as fb`", 1)[1].split("\n## ", 1)[0]
    listed = re.findall(r"^   (fusionbench[\w.]*)$", table, re.M)
    assert listed == [f"fusionbench.{m}" if m.rsplit(".", 1)[-1] == n else f"fusionbench.{m}.{n}"
                      for n, m in fb.API.items()]
