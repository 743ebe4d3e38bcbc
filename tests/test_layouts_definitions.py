"""The definitions behind fusionbench.files.layouts: each axes name's matrix against its letters and known motions,
and docs/layouts.md's tables (keys, axes, built-in layouts) and example against the module."""

import ast
from pathlib import Path

import numpy as np
import pytest

from fusionbench.files.layouts import AXES, BUILTIN_LAYOUTS, Layout, load_layout, read_layout
from fusionbench.simulation.units import DEG, G0
from tests.independent import P as P_PYINS
from tests.layouts_helpers import DIRS, LETTERS


# ------------------------------------------------------------------------------------------------ the axes


#: Known motions: (what, RFU vector, the file's x, y, z for RFU, FRD, FLU); written by hand from the definitions.
MOTIONS = [
    ("yaw rate to the left (about up)", "gyro", (0, 0, 2), {"RFU": (0, 0, 2), "FRD": (0, 0, -2), "FLU": (0, 0, 2)}),
    ("roll rate, right side down (about forward)", "gyro", (0, 3, 0),
     {"RFU": (0, 3, 0), "FRD": (3, 0, 0), "FLU": (3, 0, 0)}),
    ("pitch rate, nose up (about right)", "gyro", (5, 0, 0), {"RFU": (5, 0, 0), "FRD": (0, 5, 0), "FLU": (0, -5, 0)}),
    ("forward specific force", "accel", (0, 7, 0), {"RFU": (0, 7, 0), "FRD": (7, 0, 0), "FLU": (7, 0, 0)}),
    ("specific force to the right", "accel", (4, 0, 0), {"RFU": (4, 0, 0), "FRD": (0, 4, 0), "FLU": (0, -4, 0)}),
    ("level and still: specific force up", "accel", (0, 0, 9.8),
     {"RFU": (0, 0, 9.8), "FRD": (0, 0, -9.8), "FLU": (0, 0, 9.8)}),
]


@pytest.mark.parametrize("axes", ["RFU", "FRD", "FLU", "NED-style"])
@pytest.mark.parametrize("what,sensor,rfu,files", MOTIONS, ids=[m[0] for m in MOTIONS])
def test_known_motion_lands_on_the_right_rfu_axis(tmp_path, axes, what, sensor, rfu, files):
    v = np.array(files[LETTERS[axes]], dtype=float)
    g, a = (v, np.zeros(3)) if sensor == "gyro" else (np.zeros(3), v)
    path = tmp_path / "m.txt"
    path.write_text("".join(f"{k * 0.1} {' '.join(map(str, g))} {' '.join(map(str, a))}\n" for k in range(3)))
    imu, _ = read_layout(path, Layout(axes=axes))
    np.testing.assert_array_equal((imu.gyro if sensor == "gyro" else imu.accel)[0], np.tile(rfu, (3, 1)))
    np.testing.assert_array_equal((imu.accel if sensor == "gyro" else imu.gyro)[0], np.zeros((3, 3)))


def test_axes_matrices_are_the_letter_definitions():
    for name, M in AXES.items():
        # column j of M is the direction file axis j names, in RFU
        np.testing.assert_array_equal(M, np.array([DIRS[c] for c in LETTERS[name]], dtype=float).T)
        assert np.linalg.det(M) == 1.0  # a proper rotation: the file's axes are right-handed
    np.testing.assert_array_equal(AXES["FRD"], P_PYINS)  # the map tests/independent.py uses for pyins
    assert AXES["NED-style"] is AXES["FRD"]


# ---------------------------------------------------------------------------------------- docs/layouts.md

DOC = (Path(__file__).parents[1] / "docs" / "layouts.md").read_text()


def _table_rows(first_header):
    """First cells and whole rows of the markdown table whose header row starts with ``| first_header |``."""
    lines = DOC.splitlines()
    start = next(i for i, s in enumerate(lines[:-1])
                 if s.startswith(f"| {first_header} |") and lines[i + 1].startswith("|---"))
    rows = []
    for s in lines[start + 2:]:
        if not s.startswith("|"):
            break
        rows.append(s)
    return {row.split("|")[1].strip().strip("`"): row for row in rows}


def test_doc_documents_every_key_axes_and_builtin(tmp_path):
    from fusionbench.files.layouts import LAYOUT_KEYS

    assert sorted(_table_rows("key")) == sorted(LAYOUT_KEYS)
    assert sorted(_table_rows("name")) == sorted(BUILTIN_LAYOUTS)
    axes = _table_rows("`axes`")
    assert sorted(axes) == sorted(AXES)
    for name, row in axes.items():
        shown = row.split("`")[-2] if name != "NED-style" else None
        if shown:
            np.testing.assert_array_equal(np.array(ast.literal_eval(shown), dtype=float), AXES[name])


def test_doc_example_loads(tmp_path):
    example = DOC.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "my.toml").write_text(example)
    lay = load_layout(tmp_path / "my.toml")
    assert (lay.name, lay.delimiter, lay.time, lay.gyro, lay.time_unit, lay.gyro_unit, lay.accel_unit, lay.axes) == (
        "my-logger", ";", "ms", ("wx", "wy", "wz"), "ms", "deg/s", "g", "FLU")
    p = tmp_path / "log.txt"
    p.write_text("// bench logger\nms;wx;wy;wz;fx;fy;fz;temp\n0;0;0;90;1;0;0;20\n10;0;0;90;1;0;0;20\n")
    imu, _ = read_layout(p, lay)
    np.testing.assert_allclose(imu.t, [0.0, 0.01], rtol=0, atol=1e-18)
    np.testing.assert_allclose(imu.gyro[0, 0], [0.0, 0.0, 90 * DEG], rtol=1e-15)  # up is up in FLU
    np.testing.assert_allclose(imu.accel[0, 0], [0.0, G0, 0.0], rtol=1e-15)  # FLU x is forward
