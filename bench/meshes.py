"""Where the benchmarks find the public test meshes (the corpus described in docs/robustness.md).

The meshes are not part of the repository. ``corpus_dir()`` is the folder named by the environment
variable ``CONFORMAL_MESHES``, or else the ``shared/meshes`` folder that sits beside the repository in
the developers' workspace. Benchmarks say so and carry on with what they have when it is missing;
the tests never use it (their meshes are copies in tests/data/)."""
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def corpus_dir() -> str:
    """The folder of the public test meshes (it may not exist)."""
    return os.environ.get('CONFORMAL_MESHES') or os.path.join(os.path.dirname(ROOT), 'shared', 'meshes')
