# lucentd end to end (see daemon_basic.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_basic.py"
