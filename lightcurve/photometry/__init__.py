"""photometry subpackage (see DESIGN.md)."""
