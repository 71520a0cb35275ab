"""What several tasks share, and no task module: ``context`` (options), ``reporting`` (output and the
JSON envelope), ``hosts`` (host selection, connections, work side by side), ``state`` (the records in
``.robocore/``), ``images``, ``machine``, ``arch_checks``, ``workspace``, ``composefiles``, ``displays``,
``host_build``, ``colcon_output``, ``warmup`` and the no-op memo (``noop``, ``trees``, ``status_memo``,
``status_table``). Nothing here imports a task module (tests/test_architecture.py checks it).
"""
