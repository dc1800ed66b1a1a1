"""dynamics subpackage (see DESIGN.md)."""
