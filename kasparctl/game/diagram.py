"""The game's state machine as a mermaid diagram, drawn from the machine's own tables.

The README embeds this output; a test compares the two, so the diagram cannot
drift from the machine that runs.
"""

from __future__ import annotations

from transitions.extensions.diagrams import GraphMachine

from kasparctl.game.stages import STATES, TRANSITIONS


class _Model:
    """GraphMachine needs a model object; the diagram needs no behaviour."""


def mermaid() -> str:
    """The machine's states and transitions (with their conditions) as a mermaid diagram."""
    machine = GraphMachine(
        model=_Model(),
        states=list(STATES),
        transitions=TRANSITIONS,
        initial="idle",
        auto_transitions=False,
        show_conditions=True,
        graph_engine="mermaid",
        title="The children-as-teachers game",
    )
    lines = machine.get_graph().draw(None).splitlines()
    # Drop the styling of the current state: the README shows the machine, not a run.
    kept = [line for line in lines if not line.strip().startswith(("classDef", "Class "))]
    return "\n".join(line.rstrip() for line in kept).strip() + "\n"


if __name__ == "__main__":
    print(mermaid(), end="")
