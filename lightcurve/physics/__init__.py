"""physics subpackage (see DESIGN.md)."""
