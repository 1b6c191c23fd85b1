# lucentd clutter objects: background DRT builds, restarts, limits (see daemon_clutter.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_clutter.py"
