"""Analysis of Parquet results: reading, metrics, tables, plots, reports, animations.

Reads Parquet only and imports neither torch nor PyBullet nor the ``dispatch`` package, so a
results folder can be analysed on any machine with pyarrow, pandas, scipy and matplotlib (a road
run's network is read from the results folder too; drawing a voxel run with PyBullet borrows the
kernel's drawing of the world, :mod:`dispatch.space.physics`, when it is drawn); ``dispatch
report``, ``dispatch render`` and ``dispatch replay`` reach the command line through the
entry-point group ``dispatch.commands``
(:mod:`analysis.commands`):

* :mod:`analysis.io` - :func:`~analysis.io.open_results` on run / sweep folders;
* :mod:`analysis.metrics` - Tables I and III per allocator and N (static; per task for dynamic
  runs), taxi metrics as MATSim DRT / FleetPy name them, per-hour series;
* :mod:`analysis.timeline` - what each vehicle did when, from the events table (fleet states);
* :mod:`analysis.network` - a road run's network, read from its results folder;
* :mod:`analysis.plots`, :mod:`analysis.taxi_plots` - the figures (matplotlib, Agg canvas, no
  pyplot);
* :mod:`analysis.report` - ``dispatch report``: Markdown / HTML with tables and figures;
* :mod:`analysis.render` - ``dispatch render``: an animated GIF from PyBullet camera images
  (imports PyBullet when called), or for a road run on its map (:mod:`analysis.road_render`);
* :mod:`analysis.replay` - ``dispatch replay``: one offline HTML page that plays a run (or
  two) in the browser (:mod:`analysis.replay_data` reads the run, ``replay_assets/`` holds the
  page's script); :mod:`analysis.replay_kepler` - its kepler.gl trips export.

Importing any of these modules imports nothing heavy (matplotlib, PyBullet and Pillow are
imported inside the functions that use them).
"""
