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
