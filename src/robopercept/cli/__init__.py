"""The ``robopercept`` command line: argument parsing and printing only, one module per
command group (``main`` builds the parser from each module's ``register``)."""
