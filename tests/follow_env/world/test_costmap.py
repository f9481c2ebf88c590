"""The cost map's checks (follow_env/world/costmap.py): numpy numbers are numbers, and anything
else is a ValueError naming the argument, as follow_env/sim/checks.py promises."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.world.costmap import CostMap, cost_map_from_obstacles

COST = np.zeros((10, 10))
FREE = np.zeros((10, 10), dtype=bool)


@pytest.mark.parametrize(
    "corner",
    [
        (np.int64(0), 0.0, 0.1),
        (0.0, np.int32(-2), 0.1),
        (np.float32(0.5), 0.0, np.float32(0.1)),
        (0, 0, 1),
    ],
)
def test_numpy_and_python_numbers_place_a_cost_map(corner: tuple) -> None:
    cm = CostMap(COST, FREE, *corner)
    assert (cm.x0_m, cm.y0_m, cm.resolution_m) == tuple(float(v) for v in corner)
    assert all(type(v) is float for v in (cm.x0_m, cm.y0_m, cm.resolution_m))


@pytest.mark.parametrize(
    ("corner", "match"),
    [
        ((True, 0.0, 0.1), r"CostMap\.x0_m=True is out of range"),
        (("0", 0.0, 0.1), r"CostMap\.x0_m='0' is out of range"),
        ((0.0, np.nan, 0.1), r"CostMap\.y0_m=nan is out of range"),
        ((0.0, 0.0, 0.0), r"CostMap\.resolution_m=0\.0 is out of range: must be > 0 m"),
        ((0.0, 0.0, None), r"CostMap\.resolution_m=None is out of range"),
    ],
)
def test_a_bad_corner_or_resolution_raises_naming_it(corner: tuple, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CostMap(COST, FREE, *corner)


def test_numpy_numbers_rasterise_as_python_numbers_do() -> None:
    walls = [[0.2, 0.5, 0.8, 0.5]]
    plain = cost_map_from_obstacles((0, 0, 1, 1), walls, resolution_m=0.1, body_radius_m=0.1)
    numpy = cost_map_from_obstacles(
        tuple(np.float32(v) for v in (0, 0, 1, 1)),
        np.array(walls),
        resolution_m=np.float64(0.1),
        body_radius_m=np.int64(0),
        wall_thickness_m=np.float32(0.1),
    )
    assert numpy.shape == plain.shape
    assert numpy.occupied[5].any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"resolution_m": "0.1"}, r"resolution_m='0\.1' is out of range: must be > 0 m"),
        ({"resolution_m": None}, r"resolution_m=None is out of range: must be > 0 m"),
        ({"resolution_m": 0.0}, r"resolution_m=0\.0 is out of range: must be > 0 m"),
        ({"wall_thickness_m": -0.1}, r"wall_thickness_m=-0\.1 is out of range: must be >= 0 m"),
        ({"body_radius_m": np.nan}, r"body_radius_m=nan is out of range: must be >= 0 m"),
        ({"length_scale_m": True}, r"length_scale_m=True is out of range"),
        ({"bounds": (0, 0, 1, None)}, r"bounds=\(0, 0, 1, None\) is out of range: must be four"),
        ({"bounds": (0, 0, 1)}, r"bounds=\(0, 0, 1\) is out of range: must be four"),
        ({"bounds": None}, r"bounds=None is out of range: must be four"),
        ({"bounds": ("0", 0, 1, 1)}, r"bounds=\('0', 0, 1, 1\) is out of range"),
        ({"bounds": (0, 0, 0, 1)}, r"with xmax > xmin and ymax > ymin"),
        ({"bounds": (0, 0, np.inf, 1)}, r"bounds=\(0, 0, inf, 1\) is out of range"),
        ({"walls": [["a", 0, 1, 1]]}, r"walls=\[\['a', 0, 1, 1\]\] is out of range: must be real"),
        ({"walls": [[0, 0, 1]]}, r"walls has shape \(1, 3\): must be \(n, 4\)"),
        ({"boxes": [[0, 0, 1, None]]}, r"boxes=\[\[0, 0, 1, None\]\] is out of range"),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(kwargs: dict, match: str) -> None:
    args = {"bounds": (0, 0, 1, 1), **kwargs}
    bounds = args.pop("bounds")
    with pytest.raises(ValueError, match=match):
        cost_map_from_obstacles(bounds, **args)
