set -x
T="tests/test_reliability.py tests/test_resume.py tests/test_protocols.py"
for i in 1 2; do
cd $WITHOUT && /usr/bin/time -f "nocache %e s" env PYTHONPATH=$WITHOUT $VENV/bin/pytest -p no:cacheprovider $T 2>&1 | tail -2
cd $WITH && /usr/bin/time -f "cache %e s" $VENV/bin/pytest -p no:cacheprovider $T 2>&1 | tail -2
done
