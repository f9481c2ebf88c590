"""What ``follow-tune`` prints and writes: the held-out table and the preset lines."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from policies.registry import TunableLaw

__all__ = ["preset_text", "table_text"]


def _fmt(value: float) -> str:
    return f"{value:.3g}"


def table_text(rows: Sequence[Mapping[str, Any]], summary: Mapping[str, Any]) -> str:
    """The held-out table (Markdown): per candidate its values, search score, held-out mean
    reward per episode [95 % CI], paired difference from the current preset [CI] and its
    permutation p, the one-standard-error flag, turn accel RMS and failures; then the verdict
    (a trial is better by the rule of :func:`eval.tuning.holdout.choose`: CI above 0 and p <
    0.05)."""
    a, b = summary["holdout_seeds"]
    n_variants = len(summary["holdout_variants"])
    head = (
        f"Held-out check: seeds {a}..{b} x {n_variants} variants "
        f"({', '.join(summary['holdout_variants'])}) = {(b - a + 1) * n_variants} "
        "episodes per candidate; mean summed reward per episode [95 % bootstrap CI]"
    )
    lines = [
        head,
        "",
        "| candidate | values | search | held-out | vs current | p | within 1 SE | turn accel RMS "
        "(rad/s²) | failed | chosen |",
        "|---|---|---:|---:|---:|---:|:---:|---:|---:|:---:|",
    ]
    for r in rows:
        values = ", ".join(f"{k}={_fmt(v)}" for k, v in r["values"].items())
        search = "" if r["search_score"] is None else f"{r['search_score']:.2f}"
        held = f"{r['holdout_mean']:.2f} [{r['ci_low']:.2f}, {r['ci_high']:.2f}]"
        diff = f"{r['diff_vs_current']:+.2f} [{r['diff_ci_low']:+.2f}, {r['diff_ci_high']:+.2f}]"
        lines.append(
            f"| {r['label']} | {values} | {search} | {held} | {diff} | {r['diff_perm_p']:.2g} | "
            f"{'yes' if r['within_1se'] else 'no'} | {r['turn_accel_rms_rad_s2']:.3f} | "
            f"{r['failed']} | {'**yes**' if r['chosen'] else ''} |"
        )
    lines += ["", f"Verdict: {summary['verdict']}."]
    return "\n".join(lines)


def preset_text(
    law: TunableLaw[Any], values: Mapping[str, float], summary: Mapping[str, Any]
) -> str:
    """The chosen parameters as a preset line to paste into the law's module, with a comment
    saying where it came from."""
    params = law.params(values)
    counts = ", ".join(f"{n} {state}" for state, n in summary["trials"].items())
    return (
        f"# {summary['command']}\n"
        f"# study {summary['study']} ({counts}), tuning seeds "
        f"{summary['tuning_seeds'][0]}..{summary['tuning_seeds'][1]}, held-out seeds "
        f"{summary['holdout_seeds'][0]}..{summary['holdout_seeds'][1]}: {summary['verdict']}\n"
        f"# {law.law}:{law.default_preset} =\n{params!r}\n"
    )
