"""kasparctl: the controller of the Kaspar robot and its children-as-teachers game."""

__version__ = "0.1.0"
