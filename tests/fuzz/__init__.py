"""The fuzz suite: hostile inputs for the public API and mutated files for every reader
(run small in `make test`, long with `python -m tests.fuzz`)."""
