//! `dmap console`: a local web server that connects to one sensor and
//! serves one page: the defect map filling in as the part is scanned, its
//! objects and verdict, the history and counters, the settings (changed
//! through the command channel) and the link's health (docs/console.md).
//!
//! `source` opens the link (a serial port, the chip model, a recording),
//! `feed` decodes it with `dmap listen`'s decoder into the `state` (one
//! `part` at a time) that `hub` shares with the `server`, which also
//! carries the page's requests (in `dmap sensor`'s words and checks) to
//! the link; `token` says who may change settings. The page is in
//! `assets/`, embedded in the binary.

mod args;
mod feed;
mod hub;
mod part;
mod server;
mod source;
mod state;
mod token;

pub use args::{ConsoleArgs, Rate};
pub use part::{DAMAGED, MAX_LINES_BYTES, MAX_PIXELS};
pub use server::EVENT_GAP;
pub use state::HISTORY;

use anyhow::{Context, Result};
use std::io::Write;
use std::sync::Arc;

pub fn run(args: &ConsoleArgs) -> Result<()> {
    let token = token::decide(args)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the web server's runtime")?;
    let listener = rt
        .block_on(tokio::net::TcpListener::bind(args.listen))
        .with_context(|| format!("cannot serve on {}", args.listen))?;
    let addr = listener.local_addr()?;
    let st = state::State {
        requests: args.input.is_none() && args.emulate.is_empty(),
        pitch_um: args.pitch_um,
        want_status: true,
        ..Default::default()
    };
    let shared: Arc<std::sync::OnceLock<Arc<hub::Hub>>> = Arc::default();
    let noted = Arc::clone(&shared);
    let note: Arc<dyn Fn(String) + Send + Sync> = Arc::new(move |what: String| {
        crate::out::warn(&what);
        if let Some(h) = noted.get() {
            h.change(|s| s.source_end = Some(what));
        }
    });
    let opened = source::open(args, note)?;
    let hub = Arc::new(hub::Hub::new(
        st,
        opened.writer,
        token.clone(),
        opened.reply_timeout,
    ));
    let _ = shared.set(Arc::clone(&hub));
    hub.change(|s| s.source = opened.name.clone());
    let url = match &token {
        Some(t) => format!("http://{addr}/?token={t}"),
        None => format!("http://{addr}/"),
    };
    let _ = writeln!(
        std::io::stderr(),
        "dmap console: serving {url} ({})",
        opened.name
    );
    if token.is_some() {
        let _ = writeln!(
            std::io::stderr(),
            "dmap console: changes of settings need the token in that address (read-only viewers need none)"
        );
    }
    let decoding = Arc::clone(&hub);
    let handle = rt.handle().clone();
    let reader = opened.reader;
    std::thread::spawn(move || feed::decode(decoding, reader, handle));
    let waking = Arc::clone(&hub);
    rt.spawn(async move { waking.wake().await });
    rt.block_on(async move {
        axum::serve(listener, server::router(hub))
            .await
            .context("serving the page")
    })
}
