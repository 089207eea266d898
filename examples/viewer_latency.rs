//! Interaction latency of `splatray view`: from a drag's input to the
//! first refreshed frame drawn in the page, in a real headless Chromium
//! (`scripts/viewer-latency.sh` runs it; docs/viewer.md).
//!
//! `cargo run --release --example viewer_latency -- SCENE [--drags N]
//! [--screenshot OUT.png] [VIEW ARGS...]`: starts `splatray view SCENE`
//! (the release binary beside this example), opens the page, waits for the
//! first refined frame, then drags N steps of 8 px (a step waits for its
//! frame, so every step is measured); the page times each camera from the
//! moment it is sent (in the pointer event) to the moment its first frame
//! is drawn. Prints the median and the 95th percentile (nearest rank) and
//! one JSON line.

#[path = "../tests/cdp/mod.rs"]
mod cdp;

use cdp::{Browser, Server, median_p95};
use std::path::PathBuf;
use std::time::Duration;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut take = |flag: &str| -> Option<String> {
        let i = args.iter().position(|a| a == flag)?;
        let v = args.get(i + 1).cloned();
        args.drain(i..(i + 2).min(args.len()));
        v
    };
    let drags: usize = take("--drags").map_or(40, |v| v.parse().expect("--drags N"));
    let shot = take("--screenshot").map(PathBuf::from);
    let window: Vec<u32> = take("--window")
        .unwrap_or_else(|| "1000,760".into())
        .split(',')
        .map(|v| v.parse().expect("--window W,H"))
        .collect();
    // The release `splatray` beside this example (target/release/examples/..).
    let exe = std::env::current_exe().expect("current exe");
    let bin = exe
        .parent()
        .and_then(|p| p.parent())
        .map(|p| p.join("splatray"))
        .filter(|p| p.exists())
        .expect("target/release/splatray: run `cargo build --release` first");
    let view_args: Vec<&str> = args.iter().map(String::as_str).collect();
    let server = Server::start(&bin, &view_args);
    let mut b = Browser::start(window[0], window[1]);
    b.open(&server.url);
    let long = Duration::from_secs(600);
    b.wait_for(
        "!!(window.viewer && viewer.hello)",
        long,
        "the page's hello",
    );
    b.wait_for(
        "viewer.frames.some(f => f.stage === 'full')",
        long,
        "the first full frame",
    );
    let hello = b.eval("viewer.hello");
    let r = b.eval(
        "(() => { const r = document.getElementById('view').getBoundingClientRect(); \
         return [r.left + r.width / 2, r.top + r.height / 2]; })()",
    );
    let (x, y) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());
    // The first camera's latency (the page's own) is not a drag's.
    b.eval("viewer.latencies = []");
    b.mouse("mousePressed", x, y, 1);
    for k in 1..=drags {
        let dx = if (k / 10) % 2 == 0 { 8.0 } else { -8.0 };
        let px = x + dx * (k % 10) as f64;
        b.mouse("mouseMoved", px, y, 1);
        b.wait_for(
            &format!("viewer.latencies.length >= {k}"),
            long,
            "the frame of a drag step",
        );
    }
    b.mouse("mouseReleased", x, y, 0);
    if let Some(out) = &shot {
        b.wait_for(
            "viewer.frames.at(-1).stage === 'refined' || viewer.frames.at(-1).stage === 'full' && viewer.hello.spp >= 4",
            long,
            "the refined frame for the screenshot",
        );
        std::fs::write(out, b.screenshot()).expect("write the screenshot");
    }
    let lat: Vec<f64> = b
        .eval("viewer.latencies")
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (median, p95) = median_p95(&lat);
    let stats = server.stats();
    println!(
        "{}: {} splats, {}x{} (preview {}x{}): {} drag steps, input to first refreshed frame median {:.1} ms, p95 {:.1} ms (max {:.1} ms); cancelled jobs {}",
        hello["name"].as_str().unwrap_or("?"),
        hello["splats"],
        hello["width"],
        hello["height"],
        hello["width"].as_u64().unwrap_or(0) / 4,
        hello["height"].as_u64().unwrap_or(0) / 4,
        lat.len(),
        median,
        p95,
        lat.iter().copied().fold(0.0, f64::max),
        stats["cancelled"],
    );
    println!(
        "{}",
        serde_json::json!({
            "scene": hello["name"], "splats": hello["splats"],
            "width": hello["width"], "height": hello["height"],
            "steps": lat.len(), "median_ms": median, "p95_ms": p95,
            "latencies_ms": lat,
        })
    );
}
