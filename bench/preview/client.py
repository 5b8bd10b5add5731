#!/usr/bin/env python3
"""A minimal page stand-in for the preview bench: opens the WebSocket of a running svetlo
preview, receives everything until the server closes, and prints one JSON line with the
number, timing and sizes of the image frames and status messages. Standard library only."""
import base64, json, os, socket, sys, time

def main(url):
    # url: http://HOST:PORT/?token=T
    rest = url.split("://", 1)[1]
    hostport, query = rest.split("/?", 1)
    host, port = hostport.rsplit(":", 1)
    s = socket.create_connection((host, int(port)))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET /ws?{query} HTTP/1.1\r\nHost: {hostport}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    f = s.makefile("rb")
    while f.readline() not in (b"\r\n", b""):
        pass
    frames, texts = [], []
    while True:
        h = f.read(2)
        if len(h) < 2:
            break
        n = h[1] & 0x7F
        if n == 126:
            n = int.from_bytes(f.read(2), "big")
        elif n == 127:
            n = int.from_bytes(f.read(8), "big")
        p = f.read(n)
        op = h[0] & 0x0F
        if op == 2:
            frames.append((time.monotonic(), len(p) + 2 + (2 if n >= 126 else 0) + (6 if n > 65535 else 0)))
        elif op == 1:
            texts.append(len(p))
        elif op == 8:
            break
    span = frames[-1][0] - frames[0][0] if len(frames) > 1 else 0.0
    print(json.dumps({
        "frames": len(frames),
        "frames_per_s": (len(frames) - 1) / span if span > 0 else 0.0,
        "bytes_per_frame": frames[0][1] if frames else 0,
        "status_messages": len(texts),
        "bytes_per_status": sum(texts) / len(texts) if texts else 0,
    }))

if __name__ == "__main__":
    main(sys.argv[1])
