//! The result line protocol (docs/protocol.md): ASCII, one record per line,
//! every line `<type>,<fields>*XXXX\n` where `XXXX` is the CRC-16/CCITT-FALSE
//! (polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR)
//! of every byte before the `*`, in upper-case hex.
//!
//! The encoder writes into fixed buffers (no allocation); the parser borrows
//! from the line it is given, so both run on the target and on the host.
//! Each line type's file holds its encoder and, beside it, its parser:
//! `header` (`H`), `row` (`R`, `D` and `S`), `object` (`O`) and `end`
//! (`E`). Framing and CRC are in `frame`, the base64 of scores in `score`,
//! field reading in `fields`, the decoded record in `line`, and `decode`
//! checks a line and hands it to its type's parser.
//!
//! Only the line level lives here: the state of a stream of lines (which
//! scan a line belongs to, their order, the images rebuilt from them)
//! needs allocation and stays in the host's `dmap listen`.

mod decode;
mod end;
mod fields;
mod frame;
mod header;
pub mod layout;
mod line;
mod object;
mod ranges;
mod row;
mod score;

pub use crate::settings::ResetCause;
pub use decode::parse;
pub use end::{DROPPED, END_FIELDS, EndInfo, TotalsField, VERDICT, encode_end};
pub use fields::ParseError;
pub use frame::{LineBuf, LineSink, MAX_LINE, MAX_ROW_LINE, Priority, crc16};
pub use header::{HeaderInfo, MAX_FW, Origin, SPREAD_KEY, VERSION, encode_header};
pub use line::Line;
pub use object::encode_object;
pub use ranges::{Q_MAX, Q_MIN};
pub use row::encode_row;
pub use score::{SCORE_CHARS, SCORES_PER_LINE, ScoreValue, decode_score, encode_score};
