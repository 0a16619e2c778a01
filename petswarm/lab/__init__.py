"""The lab around a swarm: start a run (``launch.run`` picks the clock and the kind of run; ``run`` the
wall-clock processes and what every run shares, ``run_scenario``, ``model_run``, ``lockstep_run``), supervise
processes, record a run (``records``, ``digest``), check it (``checker``), measure it (``metrics``), report it,
watch it live or replayed (``watch``), run experiments over seeds, and talk to a running swarm (``swarm``).
``arguments`` holds the option types the command and the benches share.
"""
