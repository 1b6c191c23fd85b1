# lucentd serving the probes solver: welcome.scene.solvers, switching solver at run time, probes-only bakes (see daemon_solver.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_solver.py"
