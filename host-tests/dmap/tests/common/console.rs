//! `dmap console` under test: started on a free loopback port, its
//! address read from the line it prints, ended when dropped; a plain HTTP
//! client for its API.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub struct Console {
    child: Child,
    /// `127.0.0.1:PORT`
    pub addr: String,
    /// The address it printed (with `?token=` when it has one).
    pub url: String,
    pub stderr: Arc<Mutex<String>>,
}

impl Drop for Console {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Console {
    /// `dmap console ARGS --listen 127.0.0.1:0`, once it serves.
    pub fn start(args: &[&str]) -> Console {
        let mut child = Command::new(env!("CARGO_BIN_EXE_dmap"))
            .arg("console")
            .args(args)
            .args(["--listen", "127.0.0.1:0"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starting dmap console");
        let mut lines = BufReader::new(child.stderr.take().unwrap());
        // Its own line says where it serves; a source may warn before it.
        let mut first = String::new();
        let url = loop {
            let mut line = String::new();
            if lines.read_line(&mut line).unwrap_or(0) == 0 {
                panic!("dmap console did not say where it serves: {first}");
            }
            first.push_str(&line);
            if line.starts_with("dmap console: serving ")
                && let Some(u) = line.split_whitespace().find(|w| w.starts_with("http://"))
            {
                break u.to_string();
            }
        };
        let addr = url["http://".len()..]
            .split('/')
            .next()
            .unwrap()
            .to_string();
        let stderr = Arc::new(Mutex::new(first));
        let keep = Arc::clone(&stderr);
        std::thread::spawn(move || {
            let mut rest = String::new();
            while lines.read_line(&mut rest).unwrap_or(0) > 0 {
                keep.lock().unwrap().push_str(&rest);
                rest.clear();
            }
        });
        Console {
            child,
            addr,
            url,
            stderr,
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    pub fn state(&self) -> serde_json::Value {
        let (status, body) = http(&self.addr, "GET", "/api/state", &[], "");
        assert_eq!(status, 200, "{body}");
        serde_json::from_str(&body).unwrap()
    }

    /// Polls the state until `f` holds, at most `secs` seconds.
    pub fn wait(
        &self,
        secs: u64,
        what: &str,
        f: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let until = Instant::now() + Duration::from_secs(secs);
        loop {
            let s = self.state();
            if f(&s) {
                return s;
            }
            assert!(
                Instant::now() < until,
                "no {what} within {secs} s; state: {}\nconsole: {}",
                s["counters"],
                self.stderr.lock().unwrap()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

/// One HTTP/1.1 request on the loopback: the status and the body.
pub fn http(
    addr: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let mut req = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        req += &format!("{k}: {v}\r\n");
    }
    req += "\r\n";
    req += body;
    s.write_all(req.as_bytes()).unwrap();
    let mut out = Vec::new();
    s.read_to_end(&mut out).unwrap();
    let text = String::from_utf8_lossy(&out).to_string();
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let (head, rest) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let body = if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        unchunk(rest)
    } else {
        rest.to_string()
    };
    (status, body)
}

fn unchunk(mut s: &str) -> String {
    let mut out = String::new();
    while let Some((size, rest)) = s.split_once("\r\n") {
        let n = usize::from_str_radix(size.trim(), 16).unwrap_or(0);
        if n == 0 || rest.len() < n {
            break;
        }
        out += &rest[..n];
        s = rest[n..].trim_start_matches("\r\n");
    }
    out
}

/// A `POST /api/request` of `words`, with a token header if given.
pub fn ask(addr: &str, words: &str, token: Option<&str>) -> (u16, serde_json::Value) {
    let body = serde_json::json!({ "request": words }).to_string();
    let headers: Vec<(&str, &str)> = token.map(|t| ("X-Console-Token", t)).into_iter().collect();
    let (status, text) = http(addr, "POST", "/api/request", &headers, &body);
    (
        status,
        serde_json::from_str(&text).unwrap_or(serde_json::Value::String(text)),
    )
}
