"""What each task does: load the project, plan, execute through the adapters, report.

One module per task (or a few related tasks): ``validate``, ``base_image`` (prepare-base),
``component_images`` (stage), ``build``, ``package_tests`` (test), ``sync``, ``run`` (run, down),
``release`` (release, rollback), ``observe`` (status, logs, connect), ``doctor``, ``devshell``
(shell), ``init``. What several tasks need lives in modules that import no task module:
``context`` (options), ``reporting`` (output and the JSON envelope), ``hosts`` (host selection,
connections, work side by side), ``state`` (the records in ``.robocore/``), ``images``,
``machine``, ``workspace``, ``composefiles`` and ``warmup``.
"""
