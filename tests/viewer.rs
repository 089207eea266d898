//! `splatray view` in a real headless Chromium (Debian's package, which
//! scripts/setup.sh installs; without it this test fails and says so): the
//! page loads, the first bunny frame arrives, a drag changes the view and
//! a new frame follows, the backends give identical pixels, "save scene"
//! then `splatray render` gives the page's frames byte for byte, a garbage
//! message is answered with an error and the next frame still comes,
//! closing the tab stops the render in flight, Ctrl-C stops the server;
//! after a drag, a zoom and a field-of-view change the saved scene's
//! camera is the camera the page sent.

mod cdp;

use cdp::{Browser, Server, TempDir, bytes_of};
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_splatray");
const T: Duration = Duration::from_secs(60);

fn bunny() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes/bunny.toml")
        .display()
        .to_string()
}

/// The number of frames the page has, and of them for camera `id`.
fn frames(b: &mut Browser) -> u64 {
    b.eval("viewer.frames.length").as_u64().unwrap()
}

/// Waits until the page shows the refined frame of its newest camera.
fn settle(b: &mut Browser, what: &str) {
    b.wait_for(
        "(() => { const f = viewer.lastRefined; return !!f && f.header.camera === viewer.frames.at(-1).camera \
         && viewer.frames.at(-1).stage === 'refined'; })()",
        T,
        what,
    );
}

/// `splatray render SCENE -o OUT` of the page's saved scene `text`: the
/// PNG's bytes.
fn render_saved(dir: &Path, name: &str, text: &str) -> Vec<u8> {
    render_saved_with(dir, name, text, "octree")
}

/// [`render_saved`] with `--backend backend`.
fn render_saved_with(dir: &Path, name: &str, text: &str, backend: &str) -> Vec<u8> {
    let scene = dir.join(format!("{name}.toml"));
    let out = dir.join(format!("{name}.png"));
    std::fs::write(&scene, text).unwrap();
    let r = Command::new(BIN)
        .arg("render")
        .arg(&scene)
        .arg("-o")
        .arg(&out)
        .args(["--backend", backend])
        .output()
        .unwrap();
    assert!(
        r.status.success(),
        "render {}: {}",
        scene.display(),
        String::from_utf8_lossy(&r.stderr)
    );
    std::fs::read(&out).unwrap()
}

/// The viewer of `input` serving `width` × `height` frames, refined at
/// `spp` samples a pixel.
fn serve(input: &str, width: u32, height: u32, spp: u32) -> Server {
    let (w, h, spp) = (width.to_string(), height.to_string(), spp.to_string());
    Server::start(
        Path::new(BIN),
        &[input, "--width", &w, "--height", &h, "--refine-spp", &spp],
    )
}

#[test]
fn the_viewer_in_chromium() {
    // Small frames keep it quick: 160x120, refined at 16 samples (slow
    // enough, about 0.3 s, for the tab to close while it renders).
    let mut server = serve(&bunny(), 160, 120, 16);
    let mut b = Browser::start(400, 320);
    b.open(&server.url);

    // The page loads and says hello.
    b.wait_for("!!(window.viewer && viewer.hello)", T, "the page's hello");
    assert_eq!(b.eval("document.title"), "splatray view");
    assert_eq!(b.eval("viewer.hello.width"), 160);
    let names = b.eval("viewer.hello.backends");
    assert_eq!(
        names,
        serde_json::json!(["octree", "embree"]),
        "the renderers offered"
    );

    // The first frame of the bunny arrives (unasked), then its full and
    // refined frames.
    b.wait_for("viewer.frames.length > 0", T, "the first frame");
    assert_eq!(b.eval("viewer.frames[0].stage"), "preview");
    assert_eq!(b.eval("viewer.frames[0].width"), 40);
    settle(&mut b, "the first view's refined frame");
    let first_full = bytes_of(&mut b, "viewer.lastFull.bytes");
    let cam0 = b.eval("JSON.stringify(viewer.cam)");

    // A drag changes the view and a new frame follows.
    let r = b.eval(
        "(() => { const r = document.getElementById('view').getBoundingClientRect(); \
         return [r.left + r.width / 2, r.top + r.height / 2]; })()",
    );
    let (x, y) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());
    let n = frames(&mut b);
    b.mouse("mousePressed", x, y, 1);
    for k in 1..=5 {
        b.mouse(
            "mouseMoved",
            x + 12.0 * f64::from(k),
            y + 3.0 * f64::from(k),
            1,
        );
    }
    b.mouse("mouseReleased", x + 60.0, y + 15.0, 0);
    assert_ne!(
        b.eval("JSON.stringify(viewer.cam)"),
        cam0,
        "the drag moved the camera"
    );
    b.wait_for(
        &format!("viewer.frames.length > {n} && viewer.frames.at(-1).camera > 0"),
        T,
        "a frame after the drag",
    );
    settle(&mut b, "the dragged view's refined frame");
    let octree_full = bytes_of(&mut b, "viewer.lastFull.bytes");
    let octree_refined = bytes_of(&mut b, "viewer.lastRefined.bytes");
    assert_ne!(
        octree_full, first_full,
        "the dragged view shows another image"
    );
    assert_eq!(b.eval("viewer.lastFull.header.backend"), "octree");

    // Switching the backend gives identical pixels (PNG bytes alike), and
    // the difference overlay counts no pixel that differs.
    b.eval(
        "(() => { const s = document.getElementById('backend'); s.value = 'embree'; \
         s.dispatchEvent(new Event('change')); })()",
    );
    b.wait_for(
        "viewer.lastRefined.header.backend === 'embree'",
        T,
        "embree's frames",
    );
    assert_eq!(b.eval("viewer.lastFull.header.backend"), "embree");
    assert!(
        bytes_of(&mut b, "viewer.lastFull.bytes") == octree_full,
        "embree's full frame differs from the octree's"
    );
    assert!(
        bytes_of(&mut b, "viewer.lastRefined.bytes") == octree_refined,
        "embree's refined frame differs from the octree's"
    );
    b.eval("document.getElementById('diff').click()");
    b.wait_for(
        "viewer.frames.at(-1).stage === 'diff'",
        T,
        "the difference overlay",
    );
    assert_eq!(
        b.eval("viewer.frames.at(-1).differing"),
        serde_json::json!([0])
    );

    // A click on the bunny picks its hit with both backends.
    b.mouse("mousePressed", x, y, 1);
    b.mouse("mouseReleased", x, y, 0);
    b.wait_for("viewer.picks.length > 0", T, "the pick");
    let pick = b.eval("viewer.picks[0]");
    let hits: Vec<&Value> = pick["backends"].as_array().unwrap().iter().collect();
    assert_eq!(hits.len(), 2);
    assert_eq!(hits[0]["hit"]["splat"], hits[1]["hit"]["splat"], "{pick}");

    // The key light (the bunny's directional light) aimed from the page:
    // new frames, another image.
    let n = frames(&mut b);
    b.eval(
        "(() => { const a = document.getElementById('laz'); a.value = 60; \
         a.dispatchEvent(new Event('input')); })()",
    );
    b.wait_for(
        &format!("viewer.frames.length > {n} && viewer.frames.at(-1).stage === 'refined'"),
        T,
        "the frames with the key light aimed",
    );
    assert!(
        bytes_of(&mut b, "viewer.lastRefined.bytes") != octree_refined,
        "the key light moved, the image did not"
    );

    // Save scene, then `splatray render`: the page's frames byte for byte
    // (the refined frame, which the page shows, and the full one), the
    // key light aimed as the page aimed it.
    let dir = TempDir::new("viewer");
    b.eval("viewer.sceneText = null; document.getElementById('savescene').click()");
    b.wait_for("viewer.sceneText !== null", T, "the saved scene");
    let text = b.eval("viewer.sceneText").as_str().unwrap().to_string();
    assert!(text.contains("spp = 16"), "{text}");
    let key = b.eval("viewer.frames.length && keyDirection(60, 45)");
    let key: Vec<String> = key
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.to_string())
        .collect();
    assert!(
        text.contains(&format!("direction = [{}]", key.join(", "))),
        "the key light {key:?} is not in the saved scene:\n{text}"
    );
    assert!(
        render_saved(&dir.0, "refined", &text) == bytes_of(&mut b, "viewer.lastRefined.bytes"),
        "`splatray render` of the saved scene differs from the page's refined frame:\n{text}"
    );
    b.eval("viewer.sceneText = null; viewer.send({type: 'save_scene', spp: 1})");
    b.wait_for("viewer.sceneText !== null", T, "the saved scene at 1 spp");
    let text = b.eval("viewer.sceneText").as_str().unwrap().to_string();
    assert!(
        render_saved(&dir.0, "full", &text) == bytes_of(&mut b, "viewer.lastFull.bytes"),
        "`splatray render` of the saved scene differs from the page's full frame:\n{text}"
    );

    // A garbage message gets an error, and the next frame still comes.
    let n = frames(&mut b);
    b.eval("viewer.ws.send('{ this is not a request')");
    b.wait_for("viewer.errors.length === 1", T, "the error for garbage");
    let err = b.eval("viewer.errors[0]");
    assert!(err.as_str().unwrap().contains("bad request"), "{err}");
    b.eval("viewer.ws.send(JSON.stringify({type: 'camera', id: 99, camera: {from: [0,0,0], at: [0,0,0], up: [0,1,0], fov: 40}}))");
    b.wait_for(
        "viewer.errors.length === 2",
        T,
        "the error for a degenerate camera",
    );
    b.key("ArrowLeft", 37);
    b.wait_for(
        &format!("viewer.frames.length > {n}"),
        T,
        "a frame after the errors",
    );
    settle(&mut b, "the view after the errors");
    assert_eq!(
        b.eval("viewer.ws.readyState"),
        1,
        "the socket is still open"
    );

    // Closing the tab stops the render in flight: a new view, its preview
    // arrived, the tab closed while the refined frame renders.
    let before = server.stats();
    let n = frames(&mut b);
    b.key("ArrowRight", 39);
    b.wait_for(
        &format!("viewer.frames.length > {n}"),
        T,
        "the preview before closing",
    );
    let t_close = Instant::now();
    b.close_page();
    let mut after = server.stats();
    while after["sessions"] != 0 || after["busy"] != false {
        assert!(
            t_close.elapsed() < T,
            "the server still works for a closed tab: {after}"
        );
        std::thread::sleep(Duration::from_millis(10));
        after = server.stats();
    }
    let idle = t_close.elapsed();
    assert!(
        after["cancelled"].as_u64() > before["cancelled"].as_u64(),
        "the render in flight was finished, not dropped ({before} -> {after}; idle after {idle:?})"
    );
    std::thread::sleep(Duration::from_millis(300));
    let later = server.stats();
    assert_eq!(
        later["bands"], after["bands"],
        "bands rendered after the tab closed"
    );

    // No path from the page reaches a file.
    for p in [
        "/../Cargo.toml",
        "/scenes/bunny.toml",
        "/viewer.js/../../Cargo.toml",
    ] {
        assert_eq!(server.get(p).0, 404, "{p}");
    }
    assert_eq!(server.get("/viewer.js").0, 200);

    // Ctrl-C stops the server cleanly.
    let status = server
        .interrupt(Duration::from_secs(10))
        .expect("the server stops within 10 s of Ctrl-C");
    assert!(status.success(), "{status:?}");
    assert!(
        server.stderr.lock().unwrap().contains("stopped"),
        "{}",
        server.stderr.lock().unwrap()
    );
}

/// A request over the size bound closes that socket; the server serves the
/// next page (no browser needed).
#[test]
fn an_oversized_request_is_refused() {
    let server = serve(&bunny(), 32, 24, 1);
    let connect = || {
        let s = std::net::TcpStream::connect(server.authority()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        let (ws, _) =
            tungstenite::client(format!("ws://{}/ws", server.authority()), s).expect("handshake");
        ws
    };
    let mut ws = connect();
    let hello = ws.read().unwrap();
    assert!(hello.to_text().unwrap().contains("\"hello\""));
    let big = format!("{{\"type\":\"diff\",\"pad\":\"{}\"}}", "x".repeat(20_000));
    let _ = ws.send(tungstenite::Message::text(big));
    let mut closed = false;
    for _ in 0..100 {
        match ws.read() {
            Ok(tungstenite::Message::Close(_)) | Err(_) => {
                closed = true;
                break;
            }
            Ok(_) => {}
        }
    }
    assert!(closed, "a 20 kB request was not refused");
    // The next page gets its hello and a frame.
    let mut ws = connect();
    assert!(ws.read().unwrap().to_text().unwrap().contains("\"hello\""));
    let m = ws.read().unwrap();
    assert!(m.is_binary(), "{m:?}");
}

/// A WebSocket session without a browser: the hello, then messages.
struct Session(tungstenite::WebSocket<std::net::TcpStream>);

impl Session {
    fn open(server: &Server) -> (Session, Value) {
        let s = std::net::TcpStream::connect(server.authority()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let (mut ws, _) =
            tungstenite::client(format!("ws://{}/ws", server.authority()), s).expect("handshake");
        let hello: Value = serde_json::from_str(ws.read().unwrap().to_text().unwrap()).unwrap();
        assert_eq!(hello["type"], "hello");
        (Session(ws), hello)
    }

    fn send(&mut self, v: Value) {
        self.0
            .send(tungstenite::Message::text(v.to_string()))
            .unwrap();
    }

    /// The next frame (header and PNG) whose stage is `stage`.
    fn frame(&mut self, stage: &str) -> (Value, Vec<u8>) {
        loop {
            let m = self.0.read().unwrap();
            if let tungstenite::Message::Binary(b) = m {
                let n = u32::from_le_bytes(b[..4].try_into().unwrap()) as usize;
                let header: Value = serde_json::from_slice(&b[4..4 + n]).unwrap();
                if header["stage"] == stage {
                    return (header, b[4 + n..].to_vec());
                }
            }
        }
    }

    /// The next JSON message of type `kind`.
    fn text(&mut self, kind: &str) -> Value {
        loop {
            if let tungstenite::Message::Text(t) = self.0.read().unwrap() {
                let v: Value = serde_json::from_str(t.as_str()).unwrap();
                if v["type"] == kind {
                    return v;
                }
            }
        }
    }
}

/// Point clouds get the scene `render CLOUD` makes, and "save scene" then
/// `splatray render` gives the full frame byte for byte: a coloured PCD, a
/// lidar tile far from the origin (its coordinates near 326417, 6724193:
/// the camera read back from the text keeps its f64 precision), and an
/// organised scan (`sample --organised`), which opens at its sensor's view
/// and returns to it; each from its own view and from a camera the page
/// moved.
#[test]
fn clouds_save_the_scene_of_their_frames() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data");
    let dir = TempDir::new("viewer-clouds");
    let scan = dir.0.join("scan.pcd");
    let o = Command::new(BIN)
        .arg("sample")
        .arg(data.join("bunny-mesh.ply"))
        .args([
            "--scan-from",
            "0.6,0.5,2.2",
            "--rays",
            "64,48",
            "--fov",
            "9",
        ])
        .args(["--organised", "optical", "-o"])
        .arg(&scan)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let clouds = [
        data.join("milk.pcd"),
        data.join("32-1-472-150-76.laz"),
        scan.clone(),
    ];
    for (k, path) in clouds.iter().enumerate() {
        let cloud = path.display().to_string();
        let server = serve(&cloud, 64, 48, 1);
        let (mut s, hello) = Session::open(&server);
        let organised = *path == scan;
        assert_eq!(hello["sensor"].is_object(), organised, "{hello}");
        assert_eq!(hello["camera"]["sensor"], organised, "{hello}");
        let (h, full) = s.frame("full");
        assert_eq!(h["width"], 64);
        s.send(serde_json::json!({"type": "save_scene"}));
        let text = s.text("scene")["text"].as_str().unwrap().to_string();
        assert_eq!(text.contains("intrinsics"), organised, "{text}");
        assert!(
            render_saved(&dir.0, &format!("c{k}a"), &text) == full,
            "{cloud}: the saved scene renders another image:\n{text}"
        );
        // Moved: half-way to the point looked at, a little to the side.
        let mut cam = hello["camera"].clone();
        let (from, at) = (&cam["from"], &cam["at"]);
        let mid: Vec<f64> = (0..3)
            .map(|i| {
                let (f, a) = (from[i].as_f64().unwrap(), at[i].as_f64().unwrap());
                0.5 * (f + a) + if i == 0 { 0.1 * (f - a).abs() } else { 0.0 }
            })
            .collect();
        cam["from"] = serde_json::json!(mid);
        cam["sensor"] = serde_json::json!(false);
        s.send(serde_json::json!({"type": "camera", "id": 7, "camera": cam}));
        let moved = loop {
            let (h, png) = s.frame("full");
            if h["camera"] == 7 {
                break png;
            }
        };
        assert!(
            moved != full,
            "{cloud}: the moved camera shows the same image"
        );
        // A bad key light is refused and the view kept.
        s.send(serde_json::json!({"type": "light", "direction": [0, 0, 0]}));
        assert!(
            s.text("error")["message"]
                .as_str()
                .unwrap()
                .contains("non-zero")
        );
        s.send(serde_json::json!({"type": "save_scene"}));
        let text = s.text("scene")["text"].as_str().unwrap().to_string();
        assert!(!text.contains("intrinsics"), "{text}");
        assert!(
            render_saved(&dir.0, &format!("c{k}b"), &text) == moved,
            "{cloud}: the moved view's saved scene renders another image:\n{text}"
        );
        if organised {
            // The sensor view again: the first frame's bytes.
            s.send(serde_json::json!({"type": "camera", "id": 8, "camera": hello["sensor"]}));
            let back = loop {
                let (h, png) = s.frame("full");
                if h["camera"] == 8 {
                    break png;
                }
            };
            assert!(back == full, "the sensor view shows another image");
        }
    }
}

/// A number of the saved scene's TOML (written as a float or an integer).
fn toml_f64(v: &toml::Value) -> f64 {
    v.as_float()
        .or_else(|| v.as_integer().map(|i| i as f64))
        .unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The JSON array `v` of three numbers.
fn json_vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap_or_else(|| panic!("not an array: {v}"));
    assert_eq!(a.len(), 3, "{v}");
    [0, 1, 2].map(|i| a[i].as_f64().unwrap())
}

/// The last camera the page sent (the JSON it wrote on its socket, as
/// recorded by the hook [`record_sends`] installs).
fn sent_camera(b: &mut Browser) -> Value {
    b.eval(
        "viewer.sent.map((m) => JSON.parse(m)).filter((m) => m.type === 'camera').at(-1) || null",
    )
}

/// Records every message the page writes on its socket in `viewer.sent`.
fn record_sends(b: &mut Browser) {
    b.eval(
        "(() => { const ws = viewer.ws, send = ws.send.bind(ws); viewer.sent = []; \
         ws.send = (m) => { viewer.sent.push(m); send(m); }; })()",
    );
}

/// Waits for a frame of the page's last sent camera (`stage` or any).
fn frame_of_sent(b: &mut Browser, stage: Option<&str>, what: &str) -> Value {
    let cam = sent_camera(b);
    let id = cam["id"]
        .as_u64()
        .unwrap_or_else(|| panic!("{what}: no camera sent"));
    let stage = stage.map_or(String::new(), |s| format!(" && f.stage === '{s}'"));
    b.wait_for(
        &format!("viewer.frames.some((f) => f.camera === {id}{stage})"),
        T,
        what,
    );
    cam
}

/// The saved camera is the camera the page sent: after a drag (orbit), a
/// wheel zoom and a field-of-view change (`[`), "save scene" gives a
/// `[camera]` whose `from`, `at`, `up` (unit) and `fov` are the last
/// camera message the page wrote on its socket, to the text's rounding —
/// for a scene file (the bunny) and for a cloud (the coloured PCD). The
/// frames are rendered from the same text, so a camera wrong in the text
/// would change the frames and the saved file alike; this compares the
/// text with what the page asked for.
#[test]
fn the_saved_camera_is_the_one_the_page_sent() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data");
    let inputs = [bunny(), data.join("milk.pcd").display().to_string()];
    for input in &inputs {
        let server = serve(input, 64, 48, 1);
        let mut b = Browser::start(400, 320);
        b.open(&server.url);
        b.wait_for("!!(window.viewer && viewer.hello)", T, "the page's hello");
        b.wait_for("viewer.frames.length > 0", T, "the first frame");
        record_sends(&mut b);
        let hello = b.eval("viewer.hello");
        let (lo, hi) = (
            json_vec3(&hello["bounds"][0]),
            json_vec3(&hello["bounds"][1]),
        );
        let size = (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
        assert!(size > 0.0, "{input}: {hello}");
        let r = b.eval(
            "(() => { const r = document.getElementById('view').getBoundingClientRect(); \
             return [r.left + r.width / 2, r.top + r.height / 2]; })()",
        );
        let (x, y) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());

        // A drag: the camera orbits.
        b.mouse("mousePressed", x, y, 1);
        for k in 1..=4 {
            b.mouse(
                "mouseMoved",
                x + 10.0 * f64::from(k),
                y - 4.0 * f64::from(k),
                1,
            );
        }
        b.mouse("mouseReleased", x + 40.0, y - 16.0, 0);
        let dragged = frame_of_sent(&mut b, None, "a frame after the drag");
        let first = &hello["camera"];
        assert_ne!(
            dragged["camera"]["from"], first["from"],
            "{input}: the drag"
        );
        assert_eq!(dragged["camera"]["at"], first["at"], "{input}: the drag");

        // A wheel: the camera zooms out along its view.
        b.call(
            "Input.dispatchMouseEvent",
            serde_json::json!({"type": "mouseWheel", "x": x, "y": y, "deltaX": 0, "deltaY": 150}),
        );
        b.wait_for(
            &format!(
                "viewer.sent.length > 0 && JSON.parse(viewer.sent.at(-1)).id > {}",
                dragged["id"]
            ),
            T,
            "the zoom's camera",
        );
        let zoomed = frame_of_sent(&mut b, None, "a frame after the zoom");
        let dist = |c: &Value| {
            let (f, a) = (json_vec3(&c["from"]), json_vec3(&c["at"]));
            (0..3).map(|i| (f[i] - a[i]).powi(2)).sum::<f64>().sqrt()
        };
        let ratio = dist(&zoomed["camera"]) / dist(&dragged["camera"]);
        assert!(
            (ratio - 0.15f64.exp()).abs() < 1e-9,
            "{input}: the wheel zoomed by {ratio}"
        );

        // A field-of-view change: `[` narrows it by 3 degrees.
        b.key("[", 219);
        b.wait_for(
            &format!(
                "viewer.sent.length > 0 && JSON.parse(viewer.sent.at(-1)).id > {}",
                zoomed["id"]
            ),
            T,
            "the field of view's camera",
        );
        let sent = frame_of_sent(&mut b, Some("full"), "the full frame after the fov change");
        let fov = sent["camera"]["fov"].as_f64().unwrap();
        let fov0 = zoomed["camera"]["fov"].as_f64().unwrap();
        assert!(
            (fov - (fov0 - 3.0)).abs() < 1e-12,
            "{input}: fov {fov0} -> {fov}"
        );
        assert_eq!(sent["camera"]["sensor"], false, "{input}: {sent}");

        // "save scene": its [camera] is the camera sent.
        b.eval("viewer.sceneText = null; document.getElementById('savescene').click()");
        b.wait_for("viewer.sceneText !== null", T, "the saved scene");
        let text = b.eval("viewer.sceneText").as_str().unwrap().to_string();
        let table: toml::Table = text
            .parse()
            .unwrap_or_else(|e| panic!("{input}: the saved scene does not parse: {e}\n{text}"));
        let saved = table["camera"]
            .as_table()
            .unwrap_or_else(|| panic!("{input}: no [camera]:\n{text}"));
        let vec = |k: &str| -> [f64; 3] {
            let a = saved[k]
                .as_array()
                .unwrap_or_else(|| panic!("{input}: camera.{k}:\n{text}"));
            assert_eq!(a.len(), 3, "{input}: camera.{k}");
            [0, 1, 2].map(|i| toml_f64(&a[i]))
        };
        let c = &sent["camera"];
        let diff =
            |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
        let up = json_vec3(&c["up"]);
        let n = up.iter().map(|u| u * u).sum::<f64>().sqrt();
        let up = up.map(|u| u / n);
        let d_from = diff(vec("from"), json_vec3(&c["from"]));
        let d_at = diff(vec("at"), json_vec3(&c["at"]));
        let d_up = diff(vec("up"), up);
        let d_fov = (toml_f64(&saved["fov"]) - fov).abs();
        eprintln!(
            "{input}: saved - sent: from {d_from:e}, at {d_at:e} ({:e} of the size), up {d_up:e}, fov {d_fov:e}",
            d_from.max(d_at) / size
        );
        // The text rounds positions to 7 significant digits of the scene's
        // radius (at most 5e-7 of it: 2.5e-7 of the size), the unit up to 6
        // decimals and the fov to 3. Measured: the bunny's `from` 2.9e-7
        // off (1.7e-8 of its size 17.1), `at`, `up` and fov exact; the PCD's
        // position 1.4e-7 of its size, fov 1.7e-4 degrees.
        assert!(
            d_from <= 1e-6 * size && d_at <= 1e-6 * size,
            "{input}: the saved camera's position differs from the page's by {d_from:e} (from), {d_at:e} (at); the scene's size is {size}:\n{text}\nsent: {c}"
        );
        assert!(
            d_up <= 5.1e-7,
            "{input}: the saved up differs by {d_up:e}:\n{text}\nsent: {c}"
        );
        assert!(
            d_fov <= 5.1e-4,
            "{input}: the saved fov differs from the page's by {d_fov} degrees:\n{text}\nsent: {c}"
        );
    }
}

/// The viewer opens the hybrid scene (splats and triangles, issue 57): its
/// full frame is `splatray render scenes/hybrid.toml` at the viewer's size
/// byte for byte (a render that shows 4,726 triangle pixels at 160 × 120 in
/// `tests/triangles.rs`), Embree's frame is the octree's, the saved scene
/// keeps the three triangle models and renders the frame again, and the
/// same text without them renders another image (the triangles are in the
/// frames). Picks on the table and on the lamp shade answer a triangle's
/// id (from the number of splats on) from both backends.
#[test]
fn the_viewer_opens_the_hybrid_scene() {
    let hybrid = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hybrid.toml");
    let dir = TempDir::new("viewer-hybrid");
    let server = serve(&hybrid.display().to_string(), 64, 48, 1);
    let (mut s, hello) = Session::open(&server);
    assert_eq!(hello["width"], 64, "{hello}");
    let (h, full) = s.frame("full");
    assert_eq!(h["backend"], "octree", "{h}");

    // The scene file rendered by `render` at the viewer's size.
    let out = dir.0.join("direct.png");
    let r = Command::new(BIN)
        .arg("render")
        .arg(&hybrid)
        .args(["--width", "64", "--height", "48", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // "64x48 spp 1, 23670 splats and 158 triangles (...": the splats
    // count, the first triangle's id.
    let report = String::from_utf8_lossy(&r.stdout).to_string();
    let splats: u64 = report
        .split(" splats and 158 triangles")
        .next()
        .and_then(|h| h.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no splat and triangle count: {report}"));
    assert!(
        std::fs::read(&out).unwrap() == full,
        "the viewer's first frame is not `render scenes/hybrid.toml` at 64x48"
    );

    // Embree's frame: the same bytes.
    s.send(serde_json::json!({"type": "backend", "name": "embree"}));
    let embree = loop {
        let (h, png) = s.frame("full");
        if h["backend"] == "embree" {
            break png;
        }
    };
    assert!(embree == full, "Embree's frame of the hybrid scene differs");

    // "save scene": the triangle models kept, the frame again; without
    // them, another image.
    s.send(serde_json::json!({"type": "save_scene"}));
    let text = s.text("scene")["text"].as_str().unwrap().to_string();
    let mut table: toml::Table = text.parse().unwrap();
    let models = table["model"].as_array_mut().unwrap();
    let n = models.len();
    models.retain(|m| m.get("triangles").is_none());
    assert_eq!(n - models.len(), 3, "the saved triangle models:\n{text}");
    assert!(
        render_saved(&dir.0, "saved", &text) == full,
        "the saved hybrid scene renders another image:\n{text}"
    );
    let bare = toml::to_string(&table).unwrap();
    assert!(
        render_saved(&dir.0, "bare", &bare) != full,
        "the frame is the same without its triangles"
    );

    // The table top (left of the bunny) and the lamp shade: triangles
    // (ids from the splats' count on) on both backends, the same hit.
    for (x, y) in [(20, 32), (34, 10)] {
        s.send(serde_json::json!({"type": "pick", "x": x, "y": y}));
        let pick = s.text("pick");
        let first = &pick["backends"][0]["hit"];
        for b in pick["backends"].as_array().unwrap() {
            assert_eq!(&b["hit"], first, "({x}, {y}): {pick}");
        }
        let id = first["splat"].as_u64().unwrap_or(0);
        assert!(
            (splats..splats + 158).contains(&id),
            "({x}, {y}) is not on a triangle ({splats} splats): {pick}"
        );
    }
}
