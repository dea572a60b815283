//! `dmap console --twin` on the demo part, driven in a real headless
//! browser (Debian's chromium through chromedriver, the WebDriver client
//! fantoccini): the page shows the firmware's two objects with their boxes
//! where the object lines put them, the verdict `obj` and REJECT
//! asserted; a setting changed on the page is in the next scan's header
//! with source `c`, and after `save` and `reset` with `f`; refusals show
//! their words. The screenshot is saved as out/console/console.png and
//! its pixels checked where the boxes must be (and where they must not).
//! Needs chromium and chromium-driver (scripts/setup.sh installs them) and
//! what tests/twin.rs needs.

use crate::common;

use common::console::{Console, http};
use cvm_core::protocol::{Line, parse};
use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The index of `miss` in the header's `src=` (the settings table's order).
const MISS: usize = 9;

struct Driver(Child);

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn which(name: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?
        .to_str()?
        .split(':')
        .map(|d| Path::new(d).join(name))
        .find(|p| p.is_file())
}

async fn browser() -> (Driver, Client) {
    let (Some(driver), Some(chromium)) = (which("chromedriver"), which("chromium")) else {
        panic!(
            "chromium and chromium-driver are needed for the console's browser test: run scripts/setup.sh (apt-get install -y chromium chromium-driver)"
        );
    };
    let port = free_port();
    let child = Command::new(driver)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let driver = Driver(child);
    let caps = json!({"goog:chromeOptions": {
        "binary": chromium,
        "args": ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                 "--window-size=1400,1500", "--force-device-scale-factor=1"],
    }});
    let caps = caps.as_object().unwrap().clone();
    let until = Instant::now() + Duration::from_secs(30);
    loop {
        let c = ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
            .capabilities(caps.clone())
            .connect(&format!("http://127.0.0.1:{port}"))
            .await;
        match c {
            Ok(c) => return (driver, c),
            Err(e) if Instant::now() > until => panic!("chromedriver did not start: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
        }
    }
}

/// Waits up to `secs` for `css`'s text to satisfy `f`; returns it.
async fn text_when(c: &Client, css: &str, secs: u64, f: impl Fn(&str) -> bool) -> String {
    let until = Instant::now() + Duration::from_secs(secs);
    loop {
        let t = match c.find(Locator::Css(css)).await {
            Ok(e) => e.text().await.unwrap_or_default(),
            Err(_) => String::new(),
        };
        if f(&t) {
            return t;
        }
        assert!(
            Instant::now() < until,
            "{css} never passed within {secs} s (last: {t:?})"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

/// Types `value` into the settings row of `key` and presses its button;
/// the outcome's words once they come.
async fn set(c: &Client, key: &str, value: &str) -> String {
    let row = format!("#settings tr[data-key=\"{key}\"]");
    let input = c
        .find(Locator::Css(&format!("{row} .value-input")))
        .await
        .unwrap();
    input.clear().await.unwrap();
    input.send_keys(value).await.unwrap();
    c.find(Locator::Css(&format!("{row} button.set")))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    text_when(c, &format!("{row} .outcome"), 120, |t| {
        !t.is_empty() && t != "…"
    })
    .await
}

async fn press(c: &Client, id: &str) -> String {
    c.find(Locator::Id(id))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    text_when(c, "#action-result", 120, |t| !t.is_empty() && t != "…").await
}

/// The boxes of the object lines among `lines`: (row0, row1, col0, col1).
fn object_boxes(lines: &str) -> Vec<(u32, u32, u32, u32)> {
    lines
        .lines()
        .filter_map(|l| match parse(l.as_bytes()) {
            Ok(Line::Object(o)) => Some((o.row0, o.row1, o.col0, o.col1)),
            _ => None,
        })
        .collect()
}

fn magenta(img: &[u8], width: usize, x: f64, y: f64) -> bool {
    let at = (y.round() as usize * width + x.round() as usize) * 4;
    let p = &img[at..at + 4];
    p[0] > 200 && p[1] < 90 && p[2] > 200
}

fn check_pixels(
    png_bytes: &[u8],
    canvas: (f64, f64),
    geo: &serde_json::Value,
    boxes: &[(u32, u32, u32, u32)],
) {
    let mut dec = png::Decoder::new(std::io::Cursor::new(png_bytes));
    dec.set_transformations(png::Transformations::ALPHA | png::Transformations::EXPAND);
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba, "{info:?}");
    let w = info.width as usize;
    let (x0, y0, cell) = (
        canvas.0 + geo["x0"].as_f64().unwrap(),
        canvas.1 + geo["y0"].as_f64().unwrap(),
        geo["cell"].as_f64().unwrap(),
    );
    for &(r0, r1, c0, c1) in boxes {
        let (top, bottom) = (y0 + f64::from(r0) * cell, y0 + f64::from(r1 + 1) * cell);
        let (left, right) = (x0 + f64::from(c0) * cell, x0 + f64::from(c1 + 1) * cell);
        let (mx, my) = ((left + right) / 2.0, (top + bottom) / 2.0);
        for (what, x, y) in [
            ("left", left + 1.0, my),
            ("right", right - 1.5, my),
            ("top", mx, top + 1.0),
            ("bottom", mx, bottom - 1.5),
        ] {
            assert!(
                magenta(&buf, w, x, y),
                "no box edge ({what}) at ({x}, {y}) for object rows {r0}-{r1} cols {c0}-{c1}"
            );
        }
        assert!(
            !magenta(&buf, w, mx, my),
            "the inside of the box at rows {r0}-{r1} cols {c0}-{c1} is box-coloured"
        );
    }
    // Where no object is, no box.
    assert!(
        !magenta(&buf, w, x0 + 37.5 * cell, y0 + 1.5 * cell),
        "a box where no object is"
    );
}

#[test]
fn the_page_shows_the_demo_part_its_objects_and_changes_settings() {
    let dir = common::tmp_in("console-browser", "");
    let scan = common::demo_scan(&dir);
    let console = Console::start(&[
        "--twin",
        common::s(&scan),
        "--parts",
        "6",
        "--pitch-um",
        "334",
    ]);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let (_driver, c) = browser().await;
        c.goto(&console.url).await.unwrap();
        // The settings, once the console's own status request is answered
        // (the first run may build the firmware first).
        text_when(&c, "#settings tr[data-key=\"miss\"] .value", 900, |t| {
            !t.is_empty() && t != "?"
        })
        .await;
        assert_eq!(set(&c, "miss", "7").await, "done");
        // Refused by the board (its capacity is 39 columns), in its words.
        let said = set(&c, "cols", "100").await;
        assert!(
            said.contains("set cols=100 refused: value out of range 1..=39"),
            "{said}"
        );
        // Refused before it is sent, by the same checks as dmap sensor.
        let said = set(&c, "thr", "abc").await;
        assert!(said.contains("value of the wrong type"), "{said}");
        // The first part: 2 objects, obj, REJECT asserted.
        text_when(&c, "#verdict", 300, |t| t == "obj").await;
        let reject = c
            .find(Locator::Id("reject"))
            .await
            .unwrap()
            .text()
            .await
            .unwrap();
        assert_eq!(reject, "REJECT asserted");
        // Read at once: every event draws the table anew.
        let boxes = c
            .execute(
                "return [...document.querySelectorAll('#last-objects tbody tr')].map(r => r.dataset.box)",
                vec![],
            )
            .await
            .unwrap();
        let shown: Vec<(u32, u32, u32, u32)> = boxes
            .as_array()
            .unwrap()
            .iter()
            .map(|b| {
                let v: Vec<u32> = b.as_str().unwrap().split(',').map(|x| x.parse().unwrap()).collect();
                (v[0], v[1], v[2], v[3])
            })
            .collect();
        let (status, lines) = http(&console.addr, "GET", "/api/lines?part=last", &[], "");
        assert_eq!(status, 200);
        let fw = object_boxes(&lines);
        assert_eq!(fw.len(), 2, "the firmware's object lines: {lines}");
        assert_eq!(
            shown, fw,
            "the page's objects against the firmware's object lines"
        );
        // The boxes on the screen, where the object lines put them.
        let geo = c
            .execute("return window.consoleGeometry.last", vec![])
            .await
            .unwrap();
        let canvas = c
            .find(Locator::Id("last-map"))
            .await
            .unwrap()
            .rectangle()
            .await
            .unwrap();
        let shot = c.screenshot().await.unwrap();
        let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../out/console");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("console.png"), &shot).unwrap();
        check_pixels(&shot, (canvas.0, canvas.1), &geo, &fw);
        // The change is in the next scan's header, source c.
        text_when(
            &c,
            "#settings tr[data-key=\"miss\"] .scan-source",
            300,
            |t| t == "c",
        )
        .await;
        let s = console.state();
        let src = s["current"]["src"].as_str().unwrap().to_string();
        assert_eq!(&src[MISS..MISS + 1], "c", "{src}");
        // Saved and restarted: source f, in the header after the restart.
        assert_eq!(press(&c, "save").await, "done");
        assert_eq!(press(&c, "reset").await, "done");
        text_when(
            &c,
            "#settings tr[data-key=\"miss\"] .scan-source",
            300,
            |t| t == "f",
        )
        .await;
        let s = console.state();
        let header = s["current"]["header_line"].as_str().unwrap().to_string();
        assert!(
            header.contains("rst=sw") && header.contains("src=ffffffffffffffff"),
            "{header}"
        );
        let value = text_when(&c, "#settings tr[data-key=\"miss\"] .value", 60, |t| {
            t == "7"
        })
        .await;
        assert_eq!(value, "7");
        c.close().await.unwrap();
    });
}
