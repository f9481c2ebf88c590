"""Named blocks: fields declared once, records in numpy and in compiled code, packed from
the configuration."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from follow_env.sim.schema import Block, f8, float_column, i8, nested
from follow_env.tasks.person_follow.config import THESIS
from follow_env.tasks.person_follow.task import PARAMS, batched_sim

INNER = Block("inner", "test", [f8("a", "m", "a length"), i8("n", "", "a count", shape=(2,))])
OUTER = Block("outer", "test", [nested("inner", INNER), f8("b", "s", "a time", source="x.b")])


@njit
def _bump(records: np.ndarray) -> None:
    for i in range(records.shape[0]):
        r = records[i]
        r.inner.a += r.b
        r.inner.n[1] += 1


def test_compiled_code_reads_and_writes_fields_by_name() -> None:
    records = OUTER.zeros(3)
    records["b"] = [1.0, 2.0, 3.0]
    _bump(records)
    assert records["inner"]["a"].tolist() == [1.0, 2.0, 3.0]
    assert records["inner"]["n"][:, 1].tolist() == [1, 1, 1]


def test_a_field_declared_twice_is_refused() -> None:
    with pytest.raises(ValueError, match="declares a more than once"):
        Block("dup", "test", [f8("a", "m", ""), f8("a", "m", "")])


def test_parameters_are_packed_from_each_fields_source() -> None:
    packed = PARAMS.pack(THESIS)
    assert packed["person_h"] == THESIS.person.height_m
    assert packed["camera"]["img_w"] == THESIS.camera.width_px
    assert packed["detector"]["burst_end"] == 1.0 / THESIS.perception.burst_mean_frames
    assert packed["reward"]["collision_penalty"] == THESIS.reward.collision_penalty


def test_every_parameter_field_of_a_composed_lane_has_a_source() -> None:
    sim = batched_sim(THESIS, 1)

    def leaves(block: Block) -> list:
        out = []
        for f in block.fields:
            out += leaves(f.dtype) if isinstance(f.dtype, Block) else [f]
        return out

    for block in (sim.platform.params, PARAMS):
        for field in leaves(block):
            assert field.source is not None, field.name
            assert field.unit is not None, field.name
            assert field.doc, field.name


def test_float_columns_point_at_the_fields() -> None:
    records = OUTER.zeros(2)
    records["b"] = [5.0, 6.0]
    words = records.view(np.float64).reshape(2, -1)
    assert words[:, float_column(OUTER.dtype, ("b",))].tolist() == [5.0, 6.0]
    with pytest.raises(ValueError, match="not a float64 field"):
        float_column(OUTER.dtype, ("inner", "n"))


def test_describe_lists_every_leaf_with_its_unit() -> None:
    rows = OUTER.describe()
    assert ("inner.a", "f8", "m", "a length") in rows
    assert ("b", "f8", "s", "a time") in rows
