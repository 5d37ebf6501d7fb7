"""rerun recordings: the sink, the drawing of the station, the time series, the blueprint and the
recording child process. Kept free of imports (see :mod:`stationbed.output`)."""
