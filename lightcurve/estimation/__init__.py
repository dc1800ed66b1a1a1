"""estimation subpackage (see DESIGN.md)."""
