"""What each task does: load the project, plan, execute through the adapters, report.

One module per task, named after what a user types (``prepare-base`` is ``prepare_base``):
``validate``, ``init``, ``prepare_base``, ``stage``, ``build``, ``test``, ``dev``, ``sync``,
``run`` (run, down), ``status`` (status, logs, connect), ``shell``, ``release`` (release,
rollback), ``export``, ``doctor`` and ``fleet`` (its verbs in ``fleet_join``, ``fleet_rollout``,
``fleet_status``, ``fleet_release``; ``fleet_swarm`` is what they share). What several tasks
need lives in :mod:`robocore.commands.support`, which imports no task module.
"""
