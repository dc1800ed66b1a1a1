"""studies subpackage (see DESIGN.md)."""
