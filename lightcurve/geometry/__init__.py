"""geometry subpackage (see DESIGN.md)."""
