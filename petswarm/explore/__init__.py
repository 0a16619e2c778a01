"""``petswarm explore``: seed-driven exploration of worlds, missions and fault schedules in model time.

``generate`` draws case ``i`` of seed ``S`` (a scenario file's tables) from a generator of its own; ``runner``
runs one case in model time and keeps its record; ``properties`` judges the record (safety and liveness, each
naming the families it applies to); ``shrink`` reduces a failing case while the same property fails;
``campaign`` maps cases over local processes or a Dask cluster; ``report`` prints and plots the results.
"""
