"""The virtual module: a wide + tele phone module with every effect of thesis ch. 3.

See docs/architecture.md.

Modules, in the order data flows through them:

- :mod:`~phonestereo.sim.module`    the spec: presets ``folded-x3`` / ``nonfolded-x2`` /
  ``periscope-x5`` or a JSON; :mod:`~phonestereo.sim.random_module` draws random ones
- :mod:`~phonestereo.sim.effects`   one pure function per effect, each with its switch
- :mod:`~phonestereo.sim.capture`   the true per-capture state; rendering it
- :mod:`~phonestereo.sim.factory`   the imperfect factory calibration
- :mod:`~phonestereo.sim.scene`, :mod:`~phonestereo.sim.render`, :mod:`~phonestereo.sim.optics`,
  :mod:`~phonestereo.sim.sensor`    posed charts → radiance → 8-bit image
- :mod:`~phonestereo.sim.truth`, :mod:`~phonestereo.sim.ground_truth`   ``ground_truth.json``
- :mod:`~phonestereo.sim.scenarios`, :mod:`~phonestereo.sim.plan`   the thesis's experiments
- :mod:`~phonestereo.sim.writer`    a planned scenario → a capture set on disk

Typical use::

    from phonestereo.sim.module import load_module
    from phonestereo.sim.scenarios import plan_scenario
    from phonestereo.sim.writer import write_capture_set

    plan = plan_scenario("verification", load_module("folded-x3"), seed=1)
    write_capture_set("runs/verification", plan)

The pipeline never imports this package (import-linter contract); it reads the capture set.
"""
