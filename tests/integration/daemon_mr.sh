# lucentd's MR sessions end to end: privacy, fan-out, metrics, --mr false (see daemon_mr.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_mr.py"
