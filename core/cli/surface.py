"""``python -m core make-surface NAME N OUT.obj``."""
from ..io.obj import write_obj
from ..surfaces import SURFACES, make_surface


def add_arguments(p):
    p.add_argument('name', help=f"one of: {', '.join(SURFACES)}")
    p.add_argument('n', type=int, help='grid size (n x n vertices)')
    p.add_argument('out', help='output OBJ path')


def run(args):
    V, F = make_surface(args.name, args.n)
    write_obj(args.out, V, F)
    return 0
