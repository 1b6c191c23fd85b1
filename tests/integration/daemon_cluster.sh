# lucentd --cluster: three replicas and a Redis started here (see daemon_cluster.py).
exec /usr/bin/python3 "$(dirname "$0")/daemon_cluster.py"
