"""`simulate --power --paired`: within-group studies, analysed by the report's own inference.

The simulation is kasparctl.sim.paired's; each simulated study's analysis is
kasparctl.research.inference.compare, the paired cluster t (CR2, k - 1 degrees
of freedom) the report applies to groups that met both conditions, so each study
is analysed exactly as `kasparctl report` would analyse it. This module only joins
the two rooms, which may not import each other.
"""

from __future__ import annotations

from kasparctl.research.inference import MIN_CLUSTERS, compare
from kasparctl.sim.paired import FloatArray, PairedAnswer, paired_power
from kasparctl.sim.request import Request, arm, prepare
from kasparctl.sim.simulate import OptionError
from kasparctl.sim.studies import GROUP_MEASURES

# Passed on to compare, which since its cluster t draws no resamples for a contrast.
REPLICATES = 500


def answer(request: Request, order_effect: float, replicates: int = REPLICATES) -> PairedAnswer:
    """The power of a within-group design to tell the --compare arms apart."""
    if not request.power:
        raise OptionError("--paired: only with --power (a design's power)")
    setup = prepare(request)
    assert request.compare is not None  # prepare's checks saw to it
    name, values = request.compare
    a, b = (arm(name, value, setup) for value in values)
    design = request.design

    def analyse(
        num_a: FloatArray,
        den_a: FloatArray,
        num_b: FloatArray,
        den_b: FloatArray,
        groups: list[str],
        first: dict[str, str],
    ) -> list[float | None]:
        # One column per simulated study: every study of one size is resampled with the
        # same draws, as the report's fixed seed would resample any study of that size.
        contrasts = compare(
            f"compare {name}",
            (a.label, b.label),
            [design.measure] * num_a.shape[1],
            ((num_a, den_a), (num_b, den_b)),
            "group",
            replicates,
            setup.seed,
            (groups, groups),
            first,
        )
        assert all(c.paired for c in contrasts)
        return [c.p for c in contrasts]

    points = paired_power(
        (a, b), design.measure, design.groups_per_arm, design.studies, design.level,
        setup.seed, analyse, order_effect, MIN_CLUSTERS,
    )  # fmt: skip
    return PairedAnswer(
        name, values, design.measure, GROUP_MEASURES[design.measure], design.studies,
        design.level, setup.seed, order_effect, replicates, setup.game, (a.label, b.label),
        points,
    )  # fmt: skip
