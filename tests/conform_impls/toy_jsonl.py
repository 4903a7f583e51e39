"""A deliberately misbehaving JSON-lines implementation for the runner's own tests.

Session names steer it: '.../crash' exits, '.../hang' never answers, '.../garbage' prints non-JSON,
anything else answers metric 'x.y' with the value in the session folder's name ('.../v1.5' → 1.5).
"""

import json
import sys
import time

for line in sys.stdin:
    msg = json.loads(line)
    seq = msg["seq"]
    if msg["op"] == "hello":
        print(
            json.dumps({"seq": seq, "status": "ok", "protocol": 1, "implementation": {"name": "toy", "version": "0"}}), flush=True
        )
        continue
    if msg["op"] == "bye":
        print(json.dumps({"seq": seq, "status": "ok"}), flush=True)
        break
    if msg["op"] != "run":
        print(json.dumps({"seq": seq, "status": "error", "message": "unknown op", "findings": []}), flush=True)
        continue
    name = msg["session"].rstrip("/").rsplit("/", 1)[-1]
    if name == "crash":
        sys.exit(3)
    if name == "hang":
        time.sleep(60)
    if name == "garbage":
        print("this is not json", flush=True)
        continue
    if name == "skip":
        print(json.dumps({"seq": seq, "status": "skipped", "reason": "not implemented here"}), flush=True)
        continue
    if name == "reject":
        print(json.dumps({"seq": seq, "status": "error", "findings": [{"code": "E203", "severity": "error"}]}), flush=True)
        continue
    value = float(name[1:])
    print(
        json.dumps({"seq": seq, "status": "ok", "results": {"metrics": [{"id": "x.y", "value": value, "unit": "N"}]}}), flush=True
    )
