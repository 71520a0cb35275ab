"""What each task does: load the project, plan, execute through the adapters, report.

One module per task, named after what a user types (``prepare-base`` is ``prepare_base``):
``validate``, ``init``, ``prepare_base``, ``stage``, ``build``, ``test``, ``dev``, ``sync``,
``run``, ``down``, ``status``, ``logs``, ``shell``, ``connect``, ``release``, ``rollback``,
``export``, ``doctor``, ``desktop_password`` and ``fleet`` (its verbs in ``fleet_join``,
``fleet_rollout``, ``fleet_status`` and ``fleet_release``; ``fleet_swarm`` is what they share).
``schema`` has none: it prints :func:`robocore.config.schema.schema_json`. What several tasks
need lives in :mod:`robocore.commands.support`, which imports no task module.
"""
