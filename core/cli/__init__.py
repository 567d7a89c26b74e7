"""Command line: ``python -m core COMMAND ...``. Errors exit with code 2 and one line on stderr.

Each command lives in its own module with ``add_arguments(parser)`` and ``run(args) -> int``; the
table below names them, and a command's module is imported only when that command is parsed or runs
(``python -m core --help`` lists the commands from the table alone)."""
import argparse
import importlib
import os
import sys

from ..errors import ConformalError

# command name -> (module, one-line help)
COMMANDS = {
    'flatten': ('flatten', 'flatten a disk mesh conformally and write an OBJ with UVs'),
    'make-surface': ('surface', 'write one of the test surfaces (docs/math.md, test surfaces)'),
    'unwrap': ('unwrap', 'cut a mesh into islands along seams, flatten and pack them, write per-corner UVs'),
    'sphere': ('sphere', 'map a closed genus-0 mesh conformally to the unit sphere (OBJ out)'),
    'reconstruct': ('reconstruct', 'recover a metric on a disk mesh from travel times (CSV)'),
    'reconstruct-demo': ('reconstruct_demo', 'metric reconstruction experiment of the paper, section 8.2'),
    'geodesic': ('geodesic', 'geodesic distances from source vertices by fast marching on the conformal map'),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise ConformalError(f"{self.prog}: {message}")


def build_parser(only=None):
    """The command-line parser. ``only``: the name of the one command whose arguments are set up
    (its module imported); None sets up every command."""
    parser = _Parser(prog='python -m core', description='Conformal Flatten core tools')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    sub.required = True
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        if only is None or name == only:
            importlib.import_module(f'.{module}', __package__).add_arguments(p)
    return parser


def _command(argv):
    """The command named in ``argv`` (the first argument not starting with '-'), or None."""
    for a in argv:
        if not a.startswith('-'):
            return a if a in COMMANDS else None
    return None


def main(argv=None):
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        command = _command(argv)
        args = build_parser(command if command is not None else '').parse_args(argv)
        module = importlib.import_module(f'.{args._module}', __package__)
        return module.run(args) or 0
    except ConformalError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (``... --json | head -1``): stop quietly, and keep Python from
        # complaining again when it flushes stdout at exit
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except OSError:
            pass
        return 0
    except MemoryError:
        print("error: out of memory: the mesh is too large for this machine", file=sys.stderr)
        return 2
