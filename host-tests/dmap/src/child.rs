//! Child processes (the chip model, QEMU) that cannot outlive `dmap`.
//! `dmap` kills and reaps them itself on every way out it sees (an error,
//! SIGINT, SIGTERM, SIGHUP); SIGKILL it cannot see, so the kernel is asked
//! to send the child SIGKILL when `dmap` dies (a parent-death signal).

use std::os::unix::process::CommandExt;
use std::process::Command;

/// Makes the child of `cmd` die by SIGKILL when this process dies, however
/// it dies. The signal follows the thread that spawns the child: spawn it
/// from a thread that lives as long as `dmap` (the main thread).
pub fn dies_with_parent(cmd: &mut Command) -> &mut Command {
    // SAFETY: getpid before the fork; in the child, only async-signal-safe
    // calls (prctl, getppid, _exit) between fork and exec.
    let parent = unsafe { libc::getpid() };
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(
                libc::PR_SET_PDEATHSIG,
                libc::SIGKILL as libc::c_ulong,
                0,
                0,
                0,
            ) != 0
            {
                return Err(std::io::Error::last_os_error());
            }
            // The parent died before the request was in place: no signal
            // will come, so go now.
            if libc::getppid() != parent {
                libc::_exit(1);
            }
            Ok(())
        })
    }
}

/// Runs a build (`cargo build`) to its end. Cargo starts rustc and build
/// scripts, which a parent-death signal on cargo alone would leave
/// running: the build gets a process group of its own, and on SIGINT,
/// SIGTERM or SIGHUP `dmap` kills that whole group before it dies of the
/// signal itself. (Being outside the terminal's foreground group, the
/// build does not see a Ctrl-C itself; `dmap` passes it on this way.)
pub fn run_build(cmd: &mut Command) -> std::io::Result<std::process::ExitStatus> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    use std::sync::{Arc, Mutex};
    let group: Arc<Mutex<Option<i32>>> = Arc::new(Mutex::new(None));
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
    let handle = signals.handle();
    let seen = Arc::clone(&group);
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            if let Some(pgid) = *seen.lock().unwrap_or_else(|e| e.into_inner()) {
                // SAFETY: a plain system call on a process group of ours.
                unsafe { libc::killpg(pgid, libc::SIGKILL) };
            }
            let _ = signal_hook::low_level::emulate_default_handler(sig);
            std::process::exit(128 + sig);
        }
    });
    // Held from before the spawn until the group is known, so that a
    // signal in between finds it.
    let mut slot = group.lock().unwrap_or_else(|e| e.into_inner());
    let spawned = dies_with_parent(cmd).process_group(0).spawn();
    let mut child = match spawned {
        Ok(c) => c,
        Err(e) => {
            handle.close();
            return Err(e);
        }
    };
    *slot = Some(child.id() as i32);
    drop(slot);
    let status = child.wait();
    handle.close();
    status
}
