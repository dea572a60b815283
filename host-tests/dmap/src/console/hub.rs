//! What the decoding thread and the web server share: the state behind a
//! lock held only to change or copy it, a watch that wakes the viewers
//! (each takes the latest state when it is ready for it, so a slow one
//! skips pictures and never holds the decoding back), and the requests
//! under way on the link, each waiting for its replies by id.

use super::state::State;
use crate::sensor::{Answer, Ask};
use cvm_core::command::{Key, Request, encode_request};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::Write;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;
use tokio::sync::{mpsc, watch};

/// Longest a change waits before the viewers are woken.
pub const WAKE: Duration = Duration::from_millis(20);

/// A reply routed to the request that waits for it.
#[derive(Debug)]
pub enum Routed {
    Ok(Answer),
    Refused(String),
}

/// Where requests go: nowhere (a recording), a serial port, or the chip
/// model's receiver.
pub enum Writer {
    None,
    Port(Box<dyn Write + Send>),
    Twin(std::sync::Arc<Mutex<std::sync::mpsc::Sender<Vec<u8>>>>),
}

/// A reply as JSON: a setting's `key`, `value` and `source` letter, else
/// what the board said.
fn answer_json(a: &Answer) -> Value {
    match a {
        Answer::Value { key, value, source } => json!({
            "key": key.name(),
            "value": crate::sensor::show_value(*key, *value),
            "source": (source.as_char() as char).to_string(),
        }),
        Answer::Calibrating(n) => json!({"calibrating": n}),
        Answer::Saved => json!("saved"),
        Answer::Defaults => json!("defaults"),
        Answer::Resetting => json!("resetting"),
        other => json!(format!("{other:?}")),
    }
}

/// Why a request was not carried out: an HTTP status and the reason in words.
#[derive(Debug)]
pub struct Refusal {
    pub status: u16,
    pub reason: String,
}

impl Refusal {
    pub fn new(status: u16, reason: impl Into<String>) -> Self {
        Refusal {
            status,
            reason: reason.into(),
        }
    }
}

pub struct Hub {
    state: Mutex<State>,
    pub tick: watch::Sender<u64>,
    pending: Mutex<HashMap<u32, mpsc::UnboundedSender<Routed>>>,
    writer: Mutex<Writer>,
    next_id: AtomicU32,
    /// The token changes of settings need, if any.
    pub token: Option<String>,
    /// How long a reply may take (the chip model runs slower than silicon).
    pub reply_timeout: Duration,
    /// One request on the link at a time, as `dmap sensor` sends them.
    pub one_at_a_time: tokio::sync::Mutex<()>,
    /// Pages connected to the event stream.
    pub viewers: std::sync::atomic::AtomicUsize,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Hub {
    pub fn new(
        state: State,
        writer: Writer,
        token: Option<String>,
        reply_timeout: Duration,
    ) -> Self {
        let seed = std::collections::hash_map::RandomState::new();
        let first = std::hash::BuildHasher::hash_one(&seed, super::part::now_ms()) as u32;
        Hub {
            state: Mutex::new(state),
            tick: watch::channel(0).0,
            pending: Mutex::new(HashMap::new()),
            writer: Mutex::new(writer),
            next_id: AtomicU32::new(first >> 1),
            token,
            reply_timeout,
            one_at_a_time: tokio::sync::Mutex::new(()),
            viewers: Default::default(),
        }
    }

    pub fn state(&self) -> MutexGuard<'_, State> {
        lock(&self.state)
    }

    /// Changes the state and wakes the viewers.
    pub fn change(&self, f: impl FnOnce(&mut State)) {
        let v = self.quietly(f);
        self.tick.send_replace(v);
    }

    /// Changes the state; the viewers see it at the next wake-up
    /// ([`Hub::wake`], at most [`WAKE`] later): a row of scores need not
    /// wake every viewer as it arrives.
    pub fn quietly(&self, f: impl FnOnce(&mut State)) -> u64 {
        let mut s = self.state();
        f(&mut s);
        s.version += 1;
        s.version
    }

    /// Wakes the viewers when the state changed since they were last woken.
    pub async fn wake(&self) {
        loop {
            tokio::time::sleep(WAKE).await;
            let v = self.state().version;
            if *self.tick.borrow() != v {
                self.tick.send_replace(v);
            }
        }
    }

    /// A reply line that arrived: into the state, and to its request.
    pub fn route(&self, id: Option<u32>, r: Routed) {
        self.change(|s| match &r {
            Routed::Ok(a) => s.answer(id, a),
            Routed::Refused(why) => s.refused(id, why),
        });
        let pending = lock(&self.pending);
        // A refusal without an id is the only request under way's.
        let to = match id {
            Some(id) => pending.get(&id),
            None => pending.values().next(),
        };
        if let Some(tx) = to {
            let _ = tx.send(r);
        }
    }

    fn send(&self, id: u32, request: &Request) -> Result<(), Refusal> {
        struct Collect(Vec<u8>);
        impl cvm_core::protocol::LineSink for Collect {
            fn line(&mut self, l: &[u8], _: cvm_core::protocol::Priority) {
                self.0.extend_from_slice(l);
            }
        }
        let mut line = Collect(Vec::new());
        encode_request(id, request, &mut line);
        let failed = |e: String| Refusal::new(502, format!("the link failed: {e}"));
        match &mut *lock(&self.writer) {
            Writer::None => Err(Refusal::new(
                409,
                "a recorded stream takes no requests (the console replays it)",
            )),
            Writer::Port(w) => w
                .write_all(&line.0)
                .and_then(|()| w.flush())
                .map_err(|e| failed(e.to_string())),
            Writer::Twin(tx) => lock(tx)
                .send(line.0)
                .map_err(|_| failed("the chip model is not running".into())),
        }
    }

    /// Carries out the requests `words` stands for (in `dmap sensor`'s
    /// words, checked as it checks them), one at a time, stopping at the
    /// first refusal; the replies as JSON.
    pub async fn request(&self, words: &str) -> Result<Value, Refusal> {
        let asks = crate::sensor::twin::asks_of(words).map_err(|why| Refusal::new(400, why))?;
        if !self.state().requests {
            return Err(Refusal::new(
                409,
                "this source takes no requests (a recording, which the console replays, or the emulated board, which has no command channel)",
            ));
        }
        let _one = self.one_at_a_time.lock().await;
        let mut done = Vec::new();
        for ask in &asks {
            done.push(self.ask(ask).await?);
        }
        if asks
            .iter()
            .any(|a| matches!(a.request, Request::Save | Request::Defaults))
        {
            self.refresh_later();
        }
        Ok(json!({"request": words, "replies": done}))
    }

    async fn ask(&self, ask: &Ask) -> Result<Value, Refusal> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let (tx, mut rx) = mpsc::unbounded_channel();
        lock(&self.pending).insert(id, tx);
        let outcome = async {
            self.send(id, &ask.request)?;
            let within = match ask.request {
                Request::Save => self.reply_timeout * 5,
                _ => self.reply_timeout,
            };
            let deadline = tokio::time::Instant::now() + within;
            let mut values = Vec::new();
            loop {
                let r = tokio::time::timeout_at(deadline, rx.recv()).await;
                let a = match r {
                    Ok(Some(Routed::Ok(a))) => a,
                    Ok(Some(Routed::Refused(why))) => {
                        return Err(Refusal::new(422, format!("{} refused: {why}", ask.words)));
                    }
                    _ => {
                        return Err(Refusal::new(
                            504,
                            format!("{}: no reply within {} s", ask.words, within.as_secs_f64()),
                        ));
                    }
                };
                let finished = match (&ask.request, &a) {
                    (Request::Status, Answer::Value { .. }) => {
                        values.push(answer_json(&a));
                        values.len() == Key::ALL.len()
                    }
                    (Request::Status, _) => false,
                    (Request::Calibrate { .. }, Answer::Calibrated(_)) => false,
                    _ => true,
                };
                if finished {
                    let reply = match ask.request {
                        Request::Status => json!(values),
                        _ => answer_json(&a),
                    };
                    return Ok(json!({"id": id, "words": ask.words, "reply": reply}));
                }
            }
        }
        .await;
        lock(&self.pending).remove(&id);
        let what = match &outcome {
            Ok(v) => json!({"words": ask.words, "ok": true, "reply": v["reply"]}),
            Err(r) => json!({"words": ask.words, "ok": false, "reason": r.reason}),
        };
        self.change(|s| s.last_request = Some(what));
        outcome
    }

    /// A `status` request a little later (after a header, a reset, a save),
    /// so that the settings panel shows every value and source.
    pub fn refresh_later(&self) {
        self.change(|s| s.want_status = true);
    }
}
