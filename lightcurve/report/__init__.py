"""report subpackage (see DESIGN.md)."""
