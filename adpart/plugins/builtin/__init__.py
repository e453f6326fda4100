"""adpart's built-in plugins, registered through adpart's own entry points."""
