"""diagnosis subpackage (see DESIGN.md)."""
