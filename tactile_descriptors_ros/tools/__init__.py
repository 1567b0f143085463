"""The ``tactile`` command and the library functions behind its subcommands."""

__all__: list[str] = []
