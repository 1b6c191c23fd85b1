# lucentctl mr replay against a real lucentd (see lucentctl_mr.py).
exec /usr/bin/python3 "$(dirname "$0")/lucentctl_mr.py"
