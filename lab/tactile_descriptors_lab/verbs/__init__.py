"""The lab's `tactile` subcommands: each module's ``register(subparsers)`` is an entry point
of the ``tactile_descriptors_ros.verbs`` group (see ``lab/pyproject.toml``)."""
