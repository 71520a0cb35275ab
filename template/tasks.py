"""The tasks of this robot project: run `invoke --list` here.

They all come from robocore. Add your own tasks below and register them with
`namespace.add_task(...)`.
"""

from robocore.tasks import namespace

__all__ = ["namespace"]
