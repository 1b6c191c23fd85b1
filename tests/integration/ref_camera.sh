# lucent-ref camera: closed forms on a scene baked here, the embedded Cornell box, the flags
# (see ref_camera.py).
exec /usr/bin/python3 "$(dirname "$0")/ref_camera.py"
