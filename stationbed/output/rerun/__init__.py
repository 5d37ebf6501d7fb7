"""rerun recordings of runs and of cross-formulation checks (DESIGN §2, issue 4).

One concept per module:

* :mod:`.sdk`: the deferred ``import rerun``, the application id and the ``sim_time`` timeline;
* :mod:`.frames`: rotations and directions as rerun draws them (``C_NB``, ``C_BP``, ``C_NO``,
  the orbit position, the LVLH Euler angles, the sun), from :mod:`stationbed.model.environment`
  and :mod:`stationbed.core.rotation`;
* :mod:`.geometry`: the station's equivalent boxes, truss and mast (:func:`~.geometry.box_half_sizes`);
* :mod:`.drawing`: the 3-D scene under ``world/``, with :mod:`.cmg_arrows` (one arrow per CMG
  unit and the total ``h``) and :mod:`.elastic` (the bent centre lines of flexible arrays);
* :mod:`.series`: the rows' columns as time series under ``telemetry/``;
* :mod:`.blueprint`: the viewer layouts of a run and of a check;
* :mod:`.sink`: :class:`~.sink.RrdSink` (streaming rows into a recording) and :class:`~.sink.TeeSink`;
* :mod:`.recording`: whole recordings at once (:func:`~.recording.write_recording`,
  :func:`~.recording.write_check_recording`);
* :mod:`.child`: the recording process of ``stationbed run --rrd``.

Kept free of imports (see :mod:`stationbed.output`): the command line starts the recording child
before casadi, scipy and pydantic are imported.
"""
