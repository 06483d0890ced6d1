"""The ``smc`` commands, one module each: parse the options, call the library, print the
result (rich) and turn it into an exit code. :mod:`smccli.cli` assembles them into the app;
:mod:`~smccli.commands.console` holds what they share (the consoles, one-line messages,
progress)."""
