"""Complete examples of using the testbed from outside the project: plug-in trackers (docs/plugins.md)."""
