//! The version rules docs/protocol.md ("Versions") gives a decoder for
//! older headers: version 6 (no `sthr`, 15 `src` letters, `sthr`'s the
//! fifth missing) and versions 4 and 5 (no `sthr`, ending at `boots`)
//! parse; version 7's layout is the only one with `sthr`; a version 6
//! header with 16 letters, or a version 7 one with 15, is malformed.

use cvm_core::command::Key;
use cvm_core::protocol::{Line, ParseError, SPREAD_KEY, crc16, parse};
use cvm_core::settings::Source;

fn sealed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc16(body.as_bytes())).into_bytes()
}

const HEAD: &str = "j=5x5,cols=30,k=P,b=0,w=uniform,norm=1,fs=4095,thr=3355444,pthr=3277";
const TAIL: &str = "q=26,scores=1,dcap=4,rst=por,boots=1";

#[test]
fn spread_key_is_the_fifth_setting() {
    assert_eq!(Key::ALL[SPREAD_KEY], Key::SpreadThreshold);
}

#[test]
fn older_headers_parse_by_their_own_layout() {
    // Version 6: 15 letters, the fifth (`scores`'s in 6) read past `sthr`.
    let v6 = sealed(&format!(
        "H,v=6,fw=0.1.0,{HEAD},{TAIL},rows=10,src=ddddfdddddddddc,store=ok"
    ));
    let Ok(Line::Header(h)) = parse(&v6) else {
        panic!("{:?}", parse(&v6))
    };
    let o = h.origin.unwrap();
    assert_eq!((h.version, o.rows), (6, 10));
    assert_eq!(o.sources[SPREAD_KEY], Source::Default);
    assert_eq!(
        o.sources[SPREAD_KEY + 1],
        Source::Flash,
        "scores: the fifth letter"
    );
    assert_eq!(o.sources[Key::ALL.len() - 1], Source::Changed);
    assert_eq!(h.spread_threshold, u32::MAX, "no sthr: the channel is off");
    // Versions 4 and 5: no `rows`, `src`, `store`.
    for v in [4, 5] {
        let old = sealed(&format!("H,v={v},fw=0.1.0,{HEAD},{TAIL}"));
        let Ok(Line::Header(h)) = parse(&old) else {
            panic!("v{v}: {:?}", parse(&old))
        };
        assert_eq!((h.version, h.origin), (v, None));
    }
    // Each layout with another version's letters or fields is malformed.
    for body in [
        format!("H,v=6,fw=0.1.0,{HEAD},{TAIL},rows=10,src=dddddddddddddddd,store=ok"),
        format!(
            "H,v=7,fw=0.1.0,{HEAD},sthr=4294967295,{TAIL},rows=10,src=ddddddddddddddd,store=ok"
        ),
        format!(
            "H,v=6,fw=0.1.0,{HEAD},sthr=4294967295,{TAIL},rows=10,src=ddddddddddddddd,store=ok"
        ),
        format!("H,v=7,fw=0.1.0,{HEAD},{TAIL},rows=10,src=dddddddddddddddd,store=ok"),
        format!("H,v=5,fw=0.1.0,{HEAD},{TAIL},rows=10,src=ddddddddddddddd,store=ok"),
    ] {
        assert_eq!(
            parse(&sealed(&body)).err(),
            Some(ParseError::Format),
            "{body}"
        );
    }
}
