# lucentd against hostile or careless peers (see daemon_hardening.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_hardening.py"
