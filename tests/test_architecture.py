"""The walls of the house (docs/architecture.md), checked on the import graph.

Each rule is a function of the graph, so the same rules are also shown to fail
on a graph with a deliberately broken wall.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

import pytest
from import_graph import Edge, cycles, edges, modules

# Rooms of kasparctl, low to high: a room imports only rooms below it. Rooms on the
# same floor do not import each other.
KASPARCTL_FLOORS: dict[str, int] = {
    "kasparctl": 0,
    "kasparctl.learning": 1,
    "kasparctl.vocabulary": 1,
    "kasparctl.lexicon": 1,
    "kasparctl.config": 2,
    "kasparctl.log": 2,
    "kasparctl.body": 3,
    "kasparctl.game": 4,
    "kasparctl.sim": 5,
    "kasparctl.service": 5,
    "kasparctl.research": 5,
    "kasparctl.view": 5,
    "kasparctl.bringup": 5,
    "kasparctl.commands": 6,
    "kasparctl.cli": 7,
    "kasparctl.__main__": 8,
}
# What the game (and everything else that is not a factory's caller) may see of hal.
# hal.timerfd is the kernel's timer under hal.clock: no device, no simulated twin.
HAL_INTERFACES = ("hal", "hal.errors", "hal.clock", "hal.timerfd", "hal.keyfob.gestures")
HAL_DEVICE_ROOMS = ("hal.servos", "hal.keyfob", "hal.voice")
# Rooms that assemble real or simulated hardware and so may name implementations.
ASSEMBLERS = (
    "hal.build", "kasparctl.sim", "kasparctl.service", "kasparctl.bringup", "kasparctl.commands"
)


def room(module: str) -> str:
    """The room a module lives in: hal.servos.joints -> hal.servos; kasparctl.config itself."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _within(module: str, prefixes: Iterable[str]) -> bool:
    return any(module == prefix or module.startswith(prefix + ".") for prefix in prefixes)


def is_interface(module: str) -> bool:
    """Interfaces and settings: what any room may import of hal."""
    last = module.rsplit(".", 1)[-1]
    return module in HAL_INTERFACES or (
        room(module) in HAL_DEVICE_ROOMS and last in ("api", "settings")
    ) or module in HAL_DEVICE_ROOMS


def wall_breaches(graph: list[Edge]) -> list[str]:
    """Every import that breaks a rule of the house, as a readable line."""
    breaches = [f"import cycle: {' <-> '.join(group)}" for group in cycles(graph)]
    for edge in graph:
        source, target = edge.source, edge.target
        if source.startswith("hal") and target.startswith("kasparctl"):
            breaches.append(f"hal imports the controller: {edge}")
        if source == "kasparctl.learning.learner":
            breaches.append(f"the learner imports the project: {edge}")
        if source.endswith(".api") and not is_interface(target):
            breaches.append(f"an interface imports an implementation: {edge}")
        if target.startswith("hal") and not is_interface(target):
            same_device_room = room(source) == room(target)
            if not same_device_room and not _within(source, ASSEMBLERS):
                breaches.append(f"an implementation is imported outside a factory: {edge}")
        if source.startswith("kasparctl") and target.startswith("kasparctl"):
            source_room, target_room = room(source), room(target)
            if source_room == target_room:
                continue
            floor_of_source = KASPARCTL_FLOORS.get(source_room)
            floor_of_target = KASPARCTL_FLOORS.get(target_room)
            if floor_of_source is None or floor_of_target is None:
                breaches.append(f"a room not in the plan of the house: {edge}")
            elif floor_of_target >= floor_of_source:
                breaches.append(f"a room imports one on its own floor or above: {edge}")
    return breaches


@pytest.fixture(scope="module")
def project_edges() -> list[Edge]:
    """The import graph, read once: the tree does not change while these tests run."""
    return edges()


def test_the_house_has_no_cycles_and_every_wall_holds(project_edges: list[Edge]) -> None:
    graph = project_edges
    assert len(graph) > 100, "the import graph was not read"
    assert wall_breaches(graph) == []


def test_every_room_of_the_controller_is_on_the_plan() -> None:
    rooms = {room(name) for name in modules() if name.startswith("kasparctl")}
    assert rooms <= set(KASPARCTL_FLOORS), rooms - set(KASPARCTL_FLOORS)


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (Edge("hal.servos.api", "hal.servos.joints", 1), "import cycle"),
        (Edge("hal.servos.joints", "kasparctl.config", 1), "hal imports the controller"),
        (Edge("kasparctl.learning.learner", "kasparctl.config", 1), "the learner imports"),
        (Edge("hal.voice.api", "hal.voice.speaker", 1), "an interface imports an implementation"),
        (Edge("kasparctl.game.machine", "hal.servos.joints", 1), "outside a factory"),
        (Edge("kasparctl.game.machine", "kasparctl.sim.demo", 1), "its own floor or above"),
        (Edge("kasparctl.body.player", "kasparctl.game.machine", 1), "its own floor or above"),
        (Edge("kasparctl.research.tidy", "kasparctl.sim.demo", 1), "its own floor or above"),
    ],
)
def test_each_rule_fails_on_a_broken_wall(
    extra: Edge, expected: str, project_edges: list[Edge]
) -> None:
    breaches = wall_breaches([*project_edges, extra])
    assert any(expected in line and str(extra.source) in line for line in breaches), breaches


# -- the room list of docs/architecture.md, held against the tree ---------------------------

ROOT = Path(__file__).resolve().parent.parent
ROOM_LINE = re.compile(r"^((?:hal|kasparctl)/(?:[a-z_]+/)?)\s*(.*)$")
MODULE_LINE = re.compile(r"^  ([a-z_0-9]+)\s{2,}\S")


def documented_rooms(text: str) -> dict[str, set[str]]:
    """The rooms block of docs/architecture.md: room folder -> the module names listed."""
    block = text.split("## Rooms", 1)[1].split("```", 2)[1]
    rooms: dict[str, set[str]] = {}
    current: str | None = None
    for line in block.splitlines():
        if room_match := ROOM_LINE.match(line):
            current = room_match.group(1)
            rooms.setdefault(current, set())
        elif (module_match := MODULE_LINE.match(line)) and current is not None:
            rooms[current].add(module_match.group(1))
    return rooms


def rooms_in_tree(root: Path) -> dict[str, set[str]]:
    """Every package folder of hal/ and kasparctl/ -> its modules (without __init__)."""
    found: dict[str, set[str]] = {}
    for package in ("hal", "kasparctl"):
        for path in sorted((root / package).rglob("*.py")):
            if "__pycache__" in path.parts or path.stem == "__init__":
                continue
            folder = path.parent.relative_to(root).as_posix() + "/"
            found.setdefault(folder, set()).add(path.stem)
    return found


def test_the_room_list_names_every_module_and_only_modules_that_exist() -> None:
    documented = documented_rooms((ROOT / "docs" / "architecture.md").read_text())
    tree = rooms_in_tree(ROOT)
    assert set(documented) == set(tree), "rooms: " + str(set(documented) ^ set(tree))
    for folder, names in tree.items():
        assert documented[folder] == names, (
            folder,
            "not documented: " + ", ".join(sorted(names - documented[folder])),
            "documented, not there: " + ", ".join(sorted(documented[folder] - names)),
        )


def test_the_room_list_is_read_as_written_and_the_tree_as_it_is(tmp_path: Path) -> None:
    (tmp_path / "hal").mkdir()
    (tmp_path / "kasparctl").mkdir()
    (tmp_path / "hal" / "clock.py").write_text("")
    (tmp_path / "hal" / "errors.py").write_text("")
    doc = "## Rooms\n\n```\nhal/   the hardware\n  clock       time\n```\n"
    assert documented_rooms(doc) == {"hal/": {"clock"}}
    assert rooms_in_tree(tmp_path)["hal/"] == {"clock", "errors"}
