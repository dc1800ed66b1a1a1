"""filters subpackage (see DESIGN.md)."""
