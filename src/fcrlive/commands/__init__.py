"""CLI subcommands: one module per command, discovered by :mod:`fcrlive.cli`.

Each module defines ``NAME`` (the subcommand), ``HELP`` (one line), ``configure(parser)`` that adds
its arguments to an ``argparse.ArgumentParser``, and ``run(args) -> int`` returning the exit status.
Modules must import heavy dependencies inside ``run`` so that ``fcrlive --help`` stays fast.
"""
