"""The command layer: `gym-fetch`'s subcommands, one module each, and the only place argparse is used.

Each module has `add_parser(sub)`, which declares the subcommand's flags (the flags several commands
share, once, in `fetch.commands.flags`) with `run` set to its `run(args) -> int`; `run` turns the parsed
arguments into the typed request of one library function and calls it. `fetch.cli.SUBCOMMANDS` lists them.
"""
