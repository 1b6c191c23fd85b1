# lucentd's HTTP side for renderers: the bake's geometry and the viewer (see daemon_geometry.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_geometry.py"
