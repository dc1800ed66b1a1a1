"""css subpackage (see DESIGN.md)."""
