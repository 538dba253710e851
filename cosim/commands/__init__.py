"""One module per ``cosim`` sub-command; see :data:`cosim.cli.COMMANDS`."""
