"""Built-in plugins, registered through zooctl's own entry points like any third-party plugin."""
