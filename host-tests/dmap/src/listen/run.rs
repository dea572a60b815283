//! `dmap listen` itself: read the stream, write the images, print the
//! report, fail when the stream was damaged.

use super::args::ListenArgs;
use super::interrupt::Interruptible;
use super::json::summary_json;
use super::reader::decode_interruptible;
use super::scan::image_refusal;
use super::text::summary_text_with;
use crate::npy::write_gradient;
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

pub fn run(args: &ListenArgs) -> Result<()> {
    let max_scans = args.max_scans as usize;
    if args.port.is_some() && args.scans > max_scans {
        bail!(
            "--scans {} is more than --max-scans {max_scans}",
            args.scans
        );
    }
    let outputs: Vec<(&str, &PathBuf)> =
        [("-o", &args.output), ("--power-output", &args.power_output)]
            .into_iter()
            .filter_map(|(name, p)| p.as_ref().map(|p| (name, p)))
            .collect();
    for &(name, out) in &outputs {
        if out.as_os_str() == "-" {
            bail!("{name} -: standard output carries the summary; give the image a file name");
        }
        // Every name this run may write (OUT.npy, OUT_2.npy, ...) against the input.
        if let Some(input) = &args.input {
            for k in 0..max_scans {
                crate::out::refuse_inputs(&output_path(out, k), &[Path::new(input)])?;
            }
        }
    }
    if let (Some(a), Some(b)) = (&args.output, &args.power_output) {
        for k in 0..max_scans {
            for j in 0..max_scans {
                if crate::out::same_destination(&output_path(a, k), &output_path(b, j)) {
                    bail!(
                        "-o and --power-output would both write {}",
                        output_path(a, k).display()
                    );
                }
            }
        }
    }
    // SIGINT and SIGTERM end the stream where it is: what is complete by
    // then is reported and written (`--port --scans 0` runs until then).
    let dec = match (&args.input, &args.port) {
        (Some(p), _) if p == "-" => {
            decode_interruptible(Interruptible::new(std::io::stdin())?, 0, max_scans)?
        }
        (Some(p), _) => {
            let f = std::fs::File::open(p).with_context(|| format!("cannot open {p}"))?;
            decode_interruptible(Interruptible::new(f)?, 0, max_scans)?
        }
        (None, Some(dev)) => {
            let port = serialport::new(dev, args.baud)
                .timeout(std::time::Duration::from_secs(3600))
                .open_native()
                .with_context(|| format!("cannot open serial port {dev} at {} baud", args.baud))?;
            decode_interruptible(Interruptible::new(port)?, args.scans, max_scans)?
        }
        (None, None) => bail!("give --input FILE (or -) or --port DEV"),
    };
    let mut failures = Vec::new();
    for (k, s) in dec.scans.iter().enumerate() {
        // The size comes from what the stream claims: refuse an image that
        // what arrived does not justify rather than exhaust memory and disk.
        // A scan without its end line (cut) is not written at all: its
        // image would be partial, and an existing file (a good image of an
        // earlier run) is worth more.
        let refusal = match s.end {
            None => Some(
                "has no end line (cut): its image would be partial; an existing file is left as it was"
                    .to_string(),
            ),
            Some(_) => image_refusal(s),
        };
        for &(name, out) in &outputs {
            let path = output_path(out, k);
            match &refusal {
                Some(why) => failures.push(format!(
                    "scan {} {why}; {} not written",
                    k + 1,
                    path.display()
                )),
                None => {
                    let img = if name == "-o" {
                        s.image()
                    } else {
                        s.power_image()
                    };
                    write_gradient(&path, s.n_rows(), s.cols, &img)?
                }
            }
        }
    }
    if dec.scans.is_empty() {
        for &(_, out) in &outputs {
            failures.push(format!(
                "no scan in the stream (no header line decoded); nothing written to {}",
                out.display()
            ));
        }
    }
    let text = if args.json {
        format!("{}\n", summary_json(&dec, args.pitch_um))
    } else {
        summary_text_with(&dec, args.pitch_um)
    };
    crate::out::stdout(text.as_bytes())?;
    let damage = dec.damage();
    if !damage.is_empty() {
        failures.push(format!(
            "the stream was damaged ({}; details in the summary)",
            damage.join(", ")
        ));
    }
    if !failures.is_empty() {
        bail!("{}", failures.join("; "));
    }
    Ok(())
}

fn output_path(base: &Path, k: usize) -> PathBuf {
    if k == 0 {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    base.with_file_name(format!("{stem}_{}.npy", k + 1))
}
