//! A small Chrome DevTools Protocol client for the viewer's browser test
//! and `examples/viewer_latency.rs`: Debian's headless Chromium started
//! with a fresh profile, one page attached, JavaScript evaluated in it and
//! mouse and key events dispatched to it; and `splatray view` started on a
//! free port.

#![allow(dead_code)]

use serde_json::{Value, json};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Where Debian's chromium is (scripts/setup.sh installs it).
pub fn chromium_path() -> PathBuf {
    for p in ["/usr/bin/chromium", "/usr/bin/chromium-browser"] {
        if Path::new(p).exists() {
            return PathBuf::from(p);
        }
    }
    panic!(
        "chromium is not installed (/usr/bin/chromium): scripts/setup.sh installs Debian's \
         `chromium` package, which the viewer's browser test drives"
    );
}

/// A `splatray view` server, stopped (Ctrl-C, then killed) when dropped.
pub struct Server {
    pub child: Child,
    pub url: String,
    pub stderr: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Server {
    /// Starts `splatray view ARGS --port 0` and reads its URL.
    pub fn start(bin: &Path, args: &[&str]) -> Server {
        let mut child = Command::new(bin)
            .arg("view")
            .args(args)
            .args(["--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("splatray view starts");
        let err = child.stderr.take().expect("stderr piped");
        let stderr = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let sink = stderr.clone();
        std::thread::spawn(move || {
            let mut s = String::new();
            let mut r = BufReader::new(err);
            while r.read_line(&mut s).unwrap_or(0) > 0 {
                sink.lock().unwrap().push_str(&s);
                s.clear();
            }
        });
        let mut out = BufReader::new(child.stdout.take().expect("stdout piped"));
        let mut line = String::new();
        out.read_line(&mut line)
            .expect("splatray view prints its URL");
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://"))
            .unwrap_or_else(|| panic!("no URL in {line:?}; stderr: {}", stderr.lock().unwrap()))
            .to_string();
        Server { child, url, stderr }
    }

    /// `host:port`.
    pub fn authority(&self) -> String {
        self.url
            .trim_start_matches("http://")
            .trim_end_matches('/')
            .to_string()
    }

    /// An HTTP GET of `path`: the status code and the body.
    pub fn get(&self, path: &str) -> (u32, String) {
        let mut s = TcpStream::connect(self.authority()).expect("connect");
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            self.authority()
        )
        .unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).expect("read response");
        let status = text
            .split_whitespace()
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0);
        let body = text
            .split_once("\r\n\r\n")
            .map_or(String::new(), |(_, b)| b.to_string());
        (status, body)
    }

    /// `/stats` as JSON.
    pub fn stats(&self) -> Value {
        let (code, body) = self.get("/stats");
        assert_eq!(code, 200, "/stats: {body}");
        serde_json::from_str(&body).expect("stats are JSON")
    }

    /// Sends SIGINT (Ctrl-C) and waits up to `timeout` for the exit.
    pub fn interrupt(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let _ = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status();
        let t0 = Instant::now();
        while t0.elapsed() < timeout {
            if let Ok(Some(s)) = self.child.try_wait() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        None
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.interrupt(Duration::from_secs(3));
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// A headless Chromium and the DevTools connection to one of its pages.
pub struct Browser {
    child: Child,
    ws: tungstenite::WebSocket<TcpStream>,
    next_id: u64,
    session: Option<String>,
    target: Option<String>,
    _profile: TempDir,
}

/// A folder removed when dropped.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        let p = std::env::temp_dir().join(format!(
            "splatray-{tag}-{}-{}",
            std::process::id(),
            Instant::now().elapsed().as_nanos() ^ u128::from(rand_word())
        ));
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

fn rand_word() -> u32 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos())
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

impl Browser {
    /// Starts Chromium (headless, no sandbox, no GPU, no network of its
    /// own, a fresh profile) with a `width`×`height` window.
    pub fn start(width: u32, height: u32) -> Browser {
        let exe = chromium_path();
        let profile = TempDir::new("chromium");
        let mut child = Command::new(&exe)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--disable-dev-shm-usage",
                "--remote-debugging-port=0",
            ])
            .arg(format!("--window-size={width},{height}"))
            .arg(format!("--user-data-dir={}", profile.0.display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("{} does not start: {e}", exe.display()));
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let mut sent = false;
            let mut log = String::new();
            while err.read_line(&mut line).unwrap_or(0) > 0 {
                if !sent {
                    log.push_str(&line);
                    if let Some(i) = line.find("ws://") {
                        let _ = tx.send(Ok(line[i..].trim().to_string()));
                        sent = true;
                    }
                }
                line.clear();
            }
            if !sent {
                let _ = tx.send(Err(log));
            }
        });
        let endpoint = match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(Ok(u)) => u,
            Ok(Err(log)) => panic!("chromium exited without a DevTools endpoint:\n{log}"),
            Err(_) => panic!("chromium printed no DevTools endpoint within 60 s"),
        };
        let authority = endpoint
            .trim_start_matches("ws://")
            .split('/')
            .next()
            .unwrap()
            .to_string();
        let stream = TcpStream::connect(&authority).expect("connect to DevTools");
        stream
            .set_read_timeout(Some(Duration::from_secs(60)))
            .unwrap();
        let (ws, _) = tungstenite::client(endpoint.as_str(), stream).expect("DevTools handshake");
        Browser {
            child,
            ws,
            next_id: 0,
            session: None,
            target: None,
            _profile: profile,
        }
    }

    /// Calls `method` (on the attached page unless `browser`), returning
    /// its result; a protocol error panics.
    pub fn call_on(&mut self, method: &str, params: Value, browser: bool) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if !browser && let Some(s) = &self.session {
            msg["sessionId"] = json!(s);
        }
        self.ws
            .send(tungstenite::Message::text(msg.to_string()))
            .expect("send to DevTools");
        loop {
            let m = self.ws.read().expect("read from DevTools");
            let tungstenite::Message::Text(t) = m else {
                continue;
            };
            let v: Value = serde_json::from_str(t.as_str()).expect("DevTools sends JSON");
            if v["id"] == json!(id) {
                if let Some(e) = v.get("error") {
                    panic!("{method}: {e}");
                }
                return v["result"].clone();
            }
        }
    }

    /// [`Browser::call_on`] the page.
    pub fn call(&mut self, method: &str, params: Value) -> Value {
        self.call_on(method, params, false)
    }

    /// Opens `url` in a new page and attaches to it.
    pub fn open(&mut self, url: &str) {
        let t = self.call_on("Target.createTarget", json!({"url": url}), true);
        let target = t["targetId"].as_str().unwrap().to_string();
        let a = self.call_on(
            "Target.attachToTarget",
            json!({"targetId": target, "flatten": true}),
            true,
        );
        self.session = Some(a["sessionId"].as_str().unwrap().to_string());
        self.target = Some(target);
    }

    /// Closes the page (the tab).
    pub fn close_page(&mut self) {
        if let Some(t) = self.target.take() {
            self.call_on("Target.closeTarget", json!({"targetId": t}), true);
            self.session = None;
        }
    }

    /// Evaluates `expr` in the page (promises awaited), returning its value;
    /// an exception panics.
    pub fn eval(&mut self, expr: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expr, "awaitPromise": true, "returnByValue": true}),
        );
        if let Some(e) = r.get("exceptionDetails") {
            panic!("{expr}: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Polls `expr` until it is true, or panics after `timeout` naming
    /// `what`.
    pub fn wait_for(&mut self, expr: &str, timeout: Duration, what: &str) {
        let t0 = Instant::now();
        loop {
            if self.eval(expr) == json!(true) {
                return;
            }
            assert!(
                t0.elapsed() < timeout,
                "{what}: not within {timeout:?} ({expr})"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// A mouse event at `(x, y)` (CSS pixels).
    pub fn mouse(&mut self, kind: &str, x: f64, y: f64, buttons: u32) {
        self.call(
            "Input.dispatchMouseEvent",
            json!({"type": kind, "x": x, "y": y, "button": if buttons > 0 || kind != "mouseMoved" { "left" } else { "none" }, "buttons": buttons, "clickCount": 1}),
        );
    }

    /// A key pressed and released (`key` as DOM names it, e.g. "ArrowLeft").
    pub fn key(&mut self, key: &str, code: u32) {
        for kind in ["keyDown", "keyUp"] {
            self.call(
                "Input.dispatchKeyEvent",
                json!({"type": kind, "key": key, "code": key, "windowsVirtualKeyCode": code}),
            );
        }
    }

    /// A PNG screenshot of the page.
    pub fn screenshot(&mut self) -> Vec<u8> {
        let r = self.call("Page.captureScreenshot", json!({"format": "png"}));
        base64_decode(r["data"].as_str().expect("screenshot data"))
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Standard base64 (the screenshot's encoding).
pub fn base64_decode(s: &str) -> Vec<u8> {
    let val = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => 255,
    };
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0;
    for c in s.bytes().map(val).filter(|&v| v < 64) {
        acc = (acc << 6) | u32::from(c);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

/// The page's JSON value `expr` as bytes (a `Uint8Array` expression).
pub fn bytes_of(b: &mut Browser, expr: &str) -> Vec<u8> {
    let v = b.eval(&format!("Array.from({expr})"));
    v.as_array()
        .unwrap_or_else(|| panic!("{expr} is not an array"))
        .iter()
        .map(|x| x.as_u64().unwrap() as u8)
        .collect()
}

/// Median and 95th percentile of `xs` (nearest rank).
pub fn median_p95(xs: &[f64]) -> (f64, f64) {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = |q: f64| v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
    (rank(0.5), rank(0.95))
}
