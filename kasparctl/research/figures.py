"""The report's figures, PNG and SVG: the paper's Fig. 2 and Fig. 3, and more, ready for inference.

Every point and bar shows how many problems (or answers) it rests on, and an
interval where one makes sense: 95 % cluster-bootstrap intervals
(kasparctl.research.inference) for the conditions' means and shares, Wilson
intervals for one child's share of right answers. No label is ever cut off:
`clipped_texts` checks every text of a drawn figure against the figure (and
against its axes when the text is clipped to them); the report notes any it
finds, and the tests fail on them.

matplotlib is the optional `report` extra: the robot never imports this
module's drawing code, so matplotlib is imported only when a report draws.
Figures are drawn on matplotlib's Agg canvas directly (no pyplot), so no
display and no global backend state are involved.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hal.errors import KasparError
from kasparctl.game.phrases import Band
from kasparctl.research.children import ChildMeasures
from kasparctl.research.conditions import Condition
from kasparctl.research.inference import MEASURES, Contrast, Intervals
from kasparctl.research.output import write_bytes
from kasparctl.research.participants import NO_PARTICIPANTS, Participants
from kasparctl.research.summary import plural

INSTALL_HINT = "pip install 'kasparctl[report]'"
FORMATS = ("png", "svg")
PNG_DPI = 120
PANELS_PER_ROW = 4
# Points of Fig. 2 resting on fewer problems than this are drawn hollow: a mean of one
# or two problems is no trend.
FEW_PROBLEMS = 5
# Bars of the per-child figure: more than this many children are shown in several rows.
CHILDREN_PER_ROW = 40
# At most this many n labels under Fig. 2, and bars in the trials-to-learn histogram.
MAX_LABELLED_GUESSES = 32
# Beyond this many guesses Fig. 2 draws its lines without a marker per point.
MAX_MARKED_GUESSES = 100
MAX_PLOTTED_GUESSES = 500
MAX_BINS = 32


class FiguresUnavailable(KasparError):
    """matplotlib is not installed; the message says how to install it."""


def require_matplotlib() -> None:
    """Fail before any work when the figures cannot be drawn."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as error:
        raise FiguresUnavailable(
            f"the report's figures need matplotlib, which is not installed: {INSTALL_HINT}"
        ) from error


@dataclass
class Drawn:
    """The figures a report drew, by name, and those it left out."""

    names: list[str] = field(default_factory=list)
    # Figures left out and why ("no answer key"), for the summary.
    notes: list[str] = field(default_factory=list)
    # Figures whose drawing failed (their note says how).
    failed: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class FigureData:
    """Everything the figures draw from."""

    conditions: Sequence[Condition]
    intervals: dict[str, Intervals]
    bands: Sequence[Band]
    children: Sequence[ChildMeasures] = ()
    participants: Participants = NO_PARTICIPANTS
    contrasts: Sequence[Contrast] = ()


def figure_table(data: FigureData) -> dict[str, Callable[[], tuple[Any, str]]]:
    """Each figure's name and the function that draws it (None and why if it cannot)."""
    return {
        "entropy_by_trial": lambda: entropy_by_trial(data),
        "final_q": lambda: final_q(data.conditions),
        "trials_to_learn": lambda: trials_to_learn(data),
        "feedback_by_child": lambda: feedback_by_child(data),
        "contrasts": lambda: contrasts(data.contrasts),
    }


def draw_all(data: FigureData, out: Path) -> Drawn:
    """Draw every figure the data allow into `out`, as PNG and SVG (each written atomically)."""
    require_matplotlib()
    drawn = Drawn()
    for name, draw in figure_table(data).items():
        try:
            figure, note = draw()
        except (ValueError, TypeError, IndexError, ZeroDivisionError, OverflowError) as error:
            # Sessions the tests never imagined must not cost the rest of the report: the
            # figure is left out and the summary's notes (and stderr) say why.
            drawn.notes.append(f"{name}: not drawn, {type(error).__name__}: {error}")
            drawn.failed.append(name)
            continue
        if figure is None:
            drawn.notes.append(f"{name}: not drawn, {note}")
            continue
        clipped = clipped_texts(figure)
        if clipped:
            drawn.notes.append(f"{name}: labels cut off: {'; '.join(clipped[:3])}")
        _save(figure, out, name)
        drawn.names.append(name)
    return drawn


def drawn_texts(figure: Any) -> list[Any]:
    """Every text the figure draws (tick labels outside the view are made but not drawn)."""
    renderer = figure.canvas.get_renderer()
    drawn: list[Any] = []
    draw_text = renderer.draw_text

    def recording(*args: Any, **kwargs: Any) -> Any:
        if kwargs.get("mtext") is not None:
            drawn.append(kwargs["mtext"])
        return draw_text(*args, **kwargs)

    renderer.draw_text = recording
    try:
        # A full draw: the layout is made, then every artist draws what it shows.
        figure.draw(renderer)
    finally:
        del renderer.draw_text
    return list(dict.fromkeys(drawn))


def clipped_texts(figure: Any, tolerance: float = 0.5) -> list[str]:
    """The texts of a drawn figure that reach outside it, or outside the axes clipping them."""
    renderer = figure.canvas.get_renderer()
    bounds = figure.bbox
    found = []
    for text in drawn_texts(figure):
        if not text.get_visible() or not text.get_text().strip():
            continue
        box = text.get_window_extent(renderer)
        if box.width == 0 and box.height == 0:
            continue
        limits = [bounds]
        clip = text.get_clip_box() if text.get_clip_on() else None
        if clip is not None:
            limits.append(clip)
        for limit in limits:
            if (
                box.x0 < limit.x0 - tolerance
                or box.y0 < limit.y0 - tolerance
                or box.x1 > limit.x1 + tolerance
                or box.y1 > limit.y1 + tolerance
            ):
                found.append(f"{text.get_text()!r} at {tuple(round(v) for v in box.extents)}")
                break
    return found


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _save(figure: Any, out: Path, name: str) -> None:
    import matplotlib

    # A fixed salt and no date: the same sessions give the same SVG, so reports diff cleanly.
    with matplotlib.rc_context({"svg.hashsalt": "kasparctl"}):
        for kind in FORMATS:
            buffer = io.BytesIO()
            if kind == "png":
                figure.savefig(buffer, format="png", dpi=PNG_DPI, metadata={"Software": None})
            else:
                figure.savefig(buffer, format="svg", metadata={"Date": None})
            write_bytes(out / f"{name}.{kind}", buffer.getvalue())


def _colours(count: int) -> list[Any]:
    from matplotlib import colormaps

    palette = colormaps["tab10"]
    return [palette(index % 10) for index in range(count)]


def _short(label: str, width: int = 28) -> str:
    return label if len(label) <= width else label[: width - 1] + "…"


def entropy_by_trial(data: FigureData) -> tuple[Any, str]:
    """Fig. 2: mean entropy before guess k, with 95 % intervals, n, and the phrase bands.

    "No idea" is log2(candidates): one dotted line for each number of toys the
    problems offered (in the names game the later bags offer fewer).
    """
    conditions = [c for c in data.conditions if c.stats.entropy_by_trial]
    if not conditions:
        return None, "no trials"
    longest = max(len(c.stats.entropy_by_trial) for c in conditions)
    candidates = sorted(
        {p.record.candidates for c in conditions for p in c.problems if p.record.candidates > 1}
    ) or [max(len(p.toys) for c in conditions for p in c.problems)]
    top = max(math.log2(max(candidates)), 0.5) * 1.08
    # Problems the game gives up at 30 guesses have at most 30 points; longer ones (a
    # configured limit far higher) get their n every few guesses, so labels never pile up.
    label_every = max(1, math.ceil(longest / MAX_LABELLED_GUESSES))
    figure = _figure(8.0, 5.4 + 0.22 * len(conditions))
    grid = figure.add_gridspec(2, 1, height_ratios=[4.2, 0.5 + 0.25 * len(conditions)])
    axes = figure.add_subplot(grid[0])
    counts_axes = figure.add_subplot(grid[1], sharex=axes)
    shades = ("#e8f4e8", "#f4f4e0", "#f8ece0", "#f8e4e4")
    for index, band in enumerate(data.bands):
        if band.min >= top:
            continue
        high = min(band.max, top)
        axes.axhspan(band.min, high, color=shades[index % len(shades)], zorder=0)
        axes.text(
            longest + 0.75,
            (band.min + high) / 2,
            band.name.replace("_", " "),
            va="center",
            fontsize=8,
            color="0.3",
        )
    for count in candidates:
        level = math.log2(count)
        axes.axhline(level, color="0.45", linestyle=":", linewidth=1, zorder=1)
        axes.text(
            0.6,
            level,
            f"no idea, {count} toys",
            va="bottom",
            fontsize=7,
            color="0.3",
        )
    colours = _colours(len(conditions))
    for row, (condition, colour) in enumerate(zip(conditions, colours, strict=True)):
        found = data.intervals[condition.label]
        means = condition.stats.entropy_by_trial
        ns = condition.stats.entropy_by_trial_n
        ks = np.arange(1, len(means) + 1)
        lows = [e.low if e.low is not None else e.value for e in found.entropy_by_trial]
        highs = [e.high if e.high is not None else e.value for e in found.entropy_by_trial]
        # A line of tens of thousands of points costs Agg hundreds of megabytes: beyond
        # MAX_PLOTTED_GUESSES, every few guesses are drawn (the figure says so).
        shown = np.unique(
            np.linspace(0, len(ks) - 1, min(len(ks), MAX_PLOTTED_GUESSES)).astype(int)
        )
        axes.fill_between(
            ks[shown],
            np.array(lows, dtype=float)[shown],
            np.array(highs, dtype=float)[shown],
            color=colour,
            alpha=0.18,
            linewidth=0,
            zorder=2,
        )
        label = f"{_short(condition.label)} ({condition.stats.problems} problems)"
        axes.plot(
            ks[shown], np.array(means)[shown], color=colour, linewidth=1.5, label=label, zorder=3
        )
        if len(ks) <= MAX_MARKED_GUESSES:
            solid = np.array(ns) >= FEW_PROBLEMS
            axes.plot(ks[solid], np.array(means)[solid], "o", color=colour, markersize=4, zorder=4)
            axes.plot(
                ks[~solid],
                np.array(means)[~solid],
                "o",
                markerfacecolor="white",
                markeredgecolor=colour,
                markersize=4,
                zorder=4,
            )
        for k, n in list(zip(ks, ns, strict=True))[::label_every]:
            counts_axes.text(k, row, str(n), ha="center", va="center", fontsize=7, color=colour)
    axes.set_xlim(0.5, longest + 2.6)
    axes.set_ylim(0, top)
    axes.xaxis.get_major_locator().set_params(integer=True)
    axes.set_ylabel("entropy before the guess (bits)")
    axes.set_title(
        "Kaspar's uncertainty by guess: mean and 95 % interval (groups resampled)", fontsize=10
    )
    axes.tick_params(labelbottom=False)
    counts_axes.set_ylim(len(conditions) - 0.5, -0.5)
    counts_axes.set_yticks(
        range(len(conditions)), [_short(c.label, 22) for c in conditions], fontsize=7
    )
    thinned = longest > MAX_PLOTTED_GUESSES
    counts_axes.set_xlabel(
        "guess within a problem (n: problems with that guess"
        + (f", shown every {label_every} guesses" if label_every > 1 else "")
        + (f"; lines through {MAX_PLOTTED_GUESSES} of the guesses)" if thinned else ")")
    )
    counts_axes.tick_params(left=False)
    for side in ("top", "right", "left"):
        counts_axes.spines[side].set_visible(False)
    # Below everything: inside, the legend would hide late means or the bands' names.
    figure.legend(
        loc="outside lower center",
        ncols=min(len(conditions), 2),
        fontsize=7,
        title=f"95 % interval shaded; hollow points: fewer than {FEW_PROBLEMS} problems",
        title_fontsize=7,
    )
    return figure, ""


def final_q(conditions: Sequence[Condition]) -> tuple[Any, str]:
    """Fig. 3: the mean final Q row of learned problems, one row per correct toy (with n)."""
    panels = []
    for condition in conditions:
        by_answer: dict[str, list[dict[str, float]]] = {}
        for problem in condition.problems:
            answer = problem.answer
            if answer is None or problem.record.learned is None:
                continue
            row = dict(zip(problem.toys, problem.record.final_q, strict=True))
            by_answer.setdefault(answer, []).append(row)
        if by_answer:
            panels.append((condition, by_answer))
    if not panels:
        return None, "no learned problem with an answer key"
    toys: list[str] = []
    for condition, _ in panels:
        for problem in condition.problems:
            toys.extend(toy for toy in problem.toys if toy not in toys)
    matrices = []
    for _, by_answer in panels:
        matrix = np.full((len(toys), len(toys)), np.nan)
        for answer, rows in by_answer.items():
            for column, toy in enumerate(toys):
                values = [row[toy] for row in rows if toy in row]
                if values:
                    matrix[toys.index(answer), column] = float(np.mean(values))
        matrices.append(matrix)
    limit = max(float(np.nanmax(np.abs(m))) for m in matrices) or 1.0
    # At most four panels a row, so eight conditions stay readable on a page.
    columns = min(len(panels), PANELS_PER_ROW)
    panel_rows = math.ceil(len(panels) / columns)
    figure = _figure(1.6 + 4.4 * columns, 0.8 + 4.3 * panel_rows)
    grid = figure.subplots(panel_rows, columns, squeeze=False).ravel()
    for unused in grid[len(panels) :]:
        unused.set_axis_off()
    image = None
    annotate = len(toys) <= 8
    for axes, (condition, by_answer), matrix in zip(grid, panels, matrices, strict=False):
        image = axes.imshow(matrix, cmap="RdBu_r", vmin=-limit, vmax=limit)
        axes.set_xticks(range(len(toys)), toys, rotation=45, ha="right", fontsize=8)
        axes.set_yticks(
            range(len(toys)),
            [f"{toy} (n={len(by_answer.get(toy, []))})" for toy in toys],
            fontsize=8,
        )
        axes.set_xlabel("toy", fontsize=9)
        axes.set_ylabel("correct toy (learned problems)", fontsize=9)
        problems = sum(len(rows) for rows in by_answer.values())
        axes.set_title(f"{_short(condition.label, 34)}\n({problems} learned problems)", fontsize=9)
        if annotate:
            for (row, column), value in np.ndenumerate(matrix):
                if not np.isnan(value):
                    ink = "white" if abs(value) > 0.6 * limit else "black"
                    axes.text(
                        column, row, f"{value:.2f}", ha="center", va="center", fontsize=6, color=ink
                    )
    colourbar = figure.colorbar(image, ax=list(grid), shrink=0.8)
    colourbar.set_label("mean final Q-value", fontsize=9)
    figure.suptitle("Final Q-values by correct toy")
    return figure, ""


def trials_to_learn(data: FigureData) -> tuple[Any, str]:
    """Share of learned problems by trials to learn, with 95 % intervals and counts on bars."""
    conditions = data.conditions
    counts = [
        [len(p.record.trials) for p in c.problems if p.record.learned is not None]
        for c in conditions
    ]
    if not any(counts):
        return None, "no problem was learned"
    low = min(min(c) for c in counts if c)
    high = max(max(c) for c in counts if c)
    if high - low + 1 > MAX_BINS:
        return _wide_trials_to_learn(conditions, counts, low, high)
    bins = np.arange(low, high + 1)
    figure = _figure(8.0, 4.6)
    axes = figure.add_subplot()
    width = 0.8 / len(conditions)
    colours = _colours(len(conditions))
    tallest = 0.0
    for index, (condition, values) in enumerate(zip(conditions, counts, strict=True)):
        if not values:
            continue
        found = data.intervals[condition.label]
        tally = [values.count(int(b)) for b in bins]
        shares = [100.0 * n / len(values) for n in tally]
        below, above = [], []
        for b, share in zip(bins, shares, strict=True):
            position = int(b) - found.trials_bins_start
            estimate = (
                found.trials_share[position] if 0 <= position < len(found.trials_share) else None
            )
            if estimate is None or estimate.low is None or estimate.high is None:
                below.append(0.0)
                above.append(0.0)
            else:
                below.append(max(share - 100 * estimate.low, 0.0))
                above.append(max(100 * estimate.high - share, 0.0))
        tallest = max(tallest, *(s + a for s, a in zip(shares, above, strict=True)))
        offset = (index - (len(conditions) - 1) / 2) * width
        bars = axes.bar(
            bins + offset,
            shares,
            width=width,
            color=colours[index],
            yerr=[below, above],
            error_kw={"elinewidth": 0.8, "capsize": 2, "ecolor": "0.3"},
            label=f"{_short(condition.label)} (n={len(values)} learned)",
        )
        for bar, n, share, extra in zip(bars, tally, shares, above, strict=True):
            if n:
                # Above the interval, where no error bar crosses it.
                axes.text(
                    bar.get_x() + bar.get_width() / 2,
                    share + extra + 0.8,
                    str(n),
                    ha="center",
                    va="bottom",
                    fontsize=6,
                )
    axes.set_xticks(bins)
    axes.set_ylim(0, max(tallest * 1.18, 5.0))
    axes.set_xlabel("trials to learn (confirming greens included)")
    axes.set_ylabel("learned problems (%)")
    axes.set_title(
        "Trials to learn: share with 95 % interval (groups resampled); count on each bar",
        fontsize=10,
    )
    axes.legend(fontsize=7)
    return figure, ""


def _wide_trials_to_learn(
    conditions: Sequence[Condition], counts: list[list[int]], low: int, high: int
) -> tuple[Any, str]:
    """Trials to learn over a range too wide for a bar per value: MAX_BINS equal bins."""
    edges = np.linspace(low, high + 1, MAX_BINS + 1)
    figure = _figure(9.0, 4.6)
    axes = figure.add_subplot()
    colours = _colours(len(conditions))
    centres = (edges[:-1] + edges[1:]) / 2
    width = (edges[1] - edges[0]) * 0.8 / len(conditions)
    tallest = 0.0
    for index, (condition, values) in enumerate(zip(conditions, counts, strict=True)):
        if not values:
            continue
        tally, _ = np.histogram(values, bins=edges)
        shares = 100.0 * tally / len(values)
        tallest = max(tallest, float(shares.max()))
        offset = (index - (len(conditions) - 1) / 2) * width
        axes.bar(
            centres + offset,
            shares,
            width=width,
            color=colours[index],
            label=f"{_short(condition.label)} (n={len(values)} learned)",
        )
        for x, n, share in zip(centres + offset, tally, shares, strict=True):
            if n:
                axes.text(x, share + 0.8, str(n), ha="center", va="bottom", fontsize=6)
    axes.set_ylim(0, max(tallest * 1.18, 5.0))
    axes.set_xlabel(f"trials to learn, in {MAX_BINS} bins of {edges[1] - edges[0]:.0f}")
    axes.set_ylabel("learned problems (%)")
    axes.set_title("Trials to learn: share of learned problems; count on each bar", fontsize=10)
    axes.legend(fontsize=7)
    return figure, ""


def wilson(right: int, total: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson 95 % interval of a share right/total (0 to 1)."""
    if total == 0:
        return 0.0, 1.0
    share = right / total
    centre = (share + z * z / (2 * total)) / (1 + z * z / total)
    spread = z * math.sqrt(share * (1 - share) / total + z * z / (4 * total * total))
    spread /= 1 + z * z / total
    return max(0.0, centre - spread), min(1.0, centre + spread)


def feedback_by_child(data: FigureData) -> tuple[Any, str]:
    """Share of each child's answers that agreed with the answer key, with Wilson intervals.

    By participant where the plans name children by codes (coloured by the first
    category of participants.csv); otherwise by place in the turn order, per condition.
    """
    coded = [c for c in data.children if c.participant is not None and c.feedback.checked]
    if coded:
        return _feedback_by_participant(coded, data.participants)
    return _feedback_by_position(data.conditions)


def _feedback_by_participant(
    children: Sequence[ChildMeasures], participants: Participants
) -> tuple[Any, str]:
    from matplotlib.patches import Patch

    children = sorted(children, key=lambda c: c.label)
    categories = participants.categories()
    attribute = categories[0] if categories else None
    levels = sorted(
        {str(participants.attributes(c.participant).get(attribute)) for c in children}
        if attribute
        else {"all"}
    )
    palette = dict(zip(levels, _colours(len(levels)), strict=True))
    rows = math.ceil(len(children) / CHILDREN_PER_ROW)
    per_row = math.ceil(len(children) / rows)
    figure = _figure(max(6.0, 1.5 + 0.32 * per_row), 0.9 + 3.4 * rows)
    grid = figure.subplots(rows, 1, squeeze=False).ravel()
    for row, axes in enumerate(grid):
        mine = children[row * per_row : (row + 1) * per_row]
        shares, below, above, colours, ticks = [], [], [], [], []
        for child in mine:
            f = child.feedback
            share = f.right / f.checked
            low, high = wilson(f.right, f.checked)
            shares.append(100 * share)
            below.append(max(100 * (share - low), 0.0))
            above.append(max(100 * (high - share), 0.0))
            level = (
                str(participants.attributes(child.participant).get(attribute))
                if attribute
                else "all"
            )
            colours.append(palette[level])
            ticks.append(f"{child.label}\nn={f.checked}")
        positions = np.arange(len(mine))
        axes.bar(
            positions,
            shares,
            color=colours,
            yerr=[below, above],
            error_kw={"elinewidth": 0.8, "capsize": 2, "ecolor": "0.3"},
        )
        axes.set_xticks(positions, ticks, fontsize=6)
        axes.set_xlim(-0.7, max(len(mine), 2) - 0.3)
        axes.set_ylim(0, 100)
        axes.set_ylabel("answers agreeing with\nthe answer key (%)", fontsize=8)
    grid[0].set_title(
        "Feedback accuracy per participant\n(95 % Wilson interval; n: answers checked)",
        fontsize=10,
    )
    if attribute:
        handles = [Patch(color=palette[level], label=level) for level in levels]
        grid[0].legend(
            handles=handles, title=attribute, fontsize=7, title_fontsize=7, loc="lower right"
        )
    return figure, ""


def _feedback_by_position(conditions: Sequence[Condition]) -> tuple[Any, str]:
    tallies = [{p: f for p, f in c.feedback_by_position.items() if f.checked} for c in conditions]
    if not any(tallies):
        return None, "no session has an answer key"
    positions = sorted({p for tally in tallies for p in tally})
    figure = _figure(8.0, 4.6)
    axes = figure.add_subplot()
    width = 0.8 / len(conditions)
    colours = _colours(len(conditions))
    for index, (condition, tally) in enumerate(zip(conditions, tallies, strict=True)):
        if not tally:
            continue
        offset = (index - (len(conditions) - 1) / 2) * width
        mine = [p for p in positions if p in tally]
        shares = [100 * tally[p].right / tally[p].checked for p in mine]
        intervals = [wilson(tally[p].right, tally[p].checked) for p in mine]
        # Rounding can put a share a hair outside its own interval: never a negative bar.
        below = [max(s - 100 * low, 0.0) for s, (low, _) in zip(shares, intervals, strict=True)]
        above = [max(100 * high - s, 0.0) for s, (_, high) in zip(shares, intervals, strict=True)]
        bars = axes.bar(
            [p + offset for p in mine],
            shares,
            width=width,
            color=colours[index],
            yerr=[below, above],
            error_kw={"elinewidth": 0.8, "capsize": 2, "ecolor": "0.3"},
            label=_short(condition.label),
        )
        axes.bar_label(
            bars,
            labels=[f"n={tally[p].checked}" for p in mine],
            label_type="center",
            fontsize=6,
            rotation=90,
            color="white",
        )
    axes.set_xticks(positions, [f"child {p}" for p in positions])
    axes.set_ylim(0, 100)
    axes.set_xlabel("place in the turn order (pooled over groups: not the same children)")
    axes.set_ylabel("answers agreeing with the answer key (%)")
    axes.set_title(
        "Feedback accuracy per turn (95 % Wilson interval; n: answers checked)", fontsize=10
    )
    axes.legend(fontsize=7, loc="lower right")
    return figure, ""


_LABELS = {m.name: m.label for m in MEASURES}
_LABELS.update(
    false_green_rate="False greens, of wrong guesses",
    false_red_rate="False reds, of right guesses",
    reaction_time_mean="Reaction time, mean",
    prompts_per_answer="Prompts per answer",
    extra_presses_per_answer="Extra presses per answer",
    undos_per_answer="Undos per answer",
)


def contrasts(found: Sequence[Contrast]) -> tuple[Any, str]:
    """A forest plot of every contrast's Hedges' g with its 95 % interval."""
    shown = [c for c in found if c.hedges_g.value is not None]
    if not shown:
        return None, (
            "no contrast with an effect size (it needs two conditions that differ in one "
            "factor, or two levels of a participant attribute, each with at least two clusters)"
        )
    figure = _figure(9.0, 1.4 + 0.26 * len(shown))
    axes = figure.add_subplot()
    labels = []
    for row, contrast in enumerate(shown):
        g = contrast.hedges_g
        colour = "0.15"
        if g.low is not None and g.high is not None:
            axes.plot([g.low, g.high], [row, row], color=colour, linewidth=1.2)
        axes.plot([g.value], [row], "o", color=colour, markersize=4)
        prefix = (
            contrast.factor.removeprefix("participant ") + " " if contrast.unit == "child" else ""
        )
        labels.append(
            f"{prefix}{_short(contrast.a, 20)} - {_short(contrast.b, 20)}: "
            f"{_LABELS.get(contrast.measure, contrast.measure)} "
            f"({contrast.clusters_a}/{contrast.clusters_b} {plural(contrast.unit)})"
        )
    axes.axvline(0, color="0.5", linewidth=0.8, linestyle="--")
    axes.set_yticks(range(len(shown)), labels, fontsize=7)
    axes.set_ylim(len(shown) - 0.5, -0.5)
    axes.set_xlabel("Hedges' g (A - B, clusters' own values), 95 % interval")
    axes.set_title("Contrasts: effect sizes", fontsize=10)
    return figure, ""
