//! Child processes (the chip model, QEMU, cargo) that cannot outlive
//! `dmap`. `dmap` kills and reaps them itself on every way out it sees (an
//! error, SIGINT, SIGTERM, SIGHUP: [`Supervised`], and [`run_build`] for a
//! build's whole process group); SIGKILL it cannot see, so the kernel is
//! asked to send the child SIGKILL when `dmap` dies (a parent-death
//! signal, [`dies_with_parent`]).

use std::os::unix::process::CommandExt;
use std::process::{Child, Command, ExitStatus};
use std::sync::{Arc, Mutex, MutexGuard};

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

/// A child and what must outlive it (`D`: the directory of the files it
/// reads). Dropping it kills the child if it still runs, reaps it, and only
/// then drops `D` (fields drop after `drop`).
struct Running<D> {
    child: Child,
    _keep: D,
}

impl<D> Drop for Running<D> {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// The child, shared with the thread that handles termination signals:
/// whoever takes it out ends it.
type Shared<D> = Arc<Mutex<Option<Running<D>>>>;

fn lock<D>(shared: &Shared<D>) -> MutexGuard<'_, Option<Running<D>>> {
    shared.lock().unwrap_or_else(|e| e.into_inner())
}

/// A child process (the chip model, QEMU) that never outlives `dmap`: on
/// every way out `dmap` sees (this value dropped on an error, a closed
/// pipe or a panic; SIGINT, SIGTERM or SIGHUP) it is killed and reaped
/// before what it reads (`D`) is removed, and on SIGKILL the kernel kills
/// it ([`dies_with_parent`]). On a signal `dmap` then dies of that signal
/// as if it had not caught it.
pub struct Supervised<D: Send + 'static> {
    shared: Shared<D>,
    signals: signal_hook::iterator::Handle,
}

impl<D: Send + 'static> Supervised<D> {
    /// Installs the signal thread, then starts `cmd` (which dies with
    /// `dmap`), keeping `keep` until the child is reaped. The child is in
    /// the signal thread's reach from its start on.
    pub fn spawn(cmd: &mut Command, keep: D) -> std::io::Result<Supervised<D>> {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let shared: Shared<D> = Arc::new(Mutex::new(None));
        let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
        let me = Supervised {
            shared: shared.clone(),
            signals: signals.handle(),
        };
        std::thread::spawn(move || {
            if let Some(sig) = signals.forever().next() {
                drop(lock(&shared).take());
                let _ = signal_hook::low_level::emulate_default_handler(sig);
                std::process::exit(128 + sig);
            }
        });
        // Held from before the spawn until the child is in it, so that a
        // signal in between finds the child to end.
        let mut slot = lock(&me.shared);
        let child = dies_with_parent(cmd).spawn()?;
        *slot = Some(Running { child, _keep: keep });
        drop(slot);
        Ok(me)
    }

    /// `f` on the child, unless the signal thread has taken it.
    pub fn with_child<R>(&self, f: impl FnOnce(&mut Child) -> R) -> Option<R> {
        lock(&self.shared).as_mut().map(|r| f(&mut r.child))
    }

    /// Waits for the child's exit status without holding the child away
    /// from the signal thread.
    pub fn wait(&self) -> std::io::Result<ExitStatus> {
        loop {
            if let Some(status) = self.with_child(|c| c.try_wait()).transpose()?.flatten() {
                return Ok(status);
            }
            // Gone: taken by the signal thread, which ends the process.
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }
}

impl<D: Send + 'static> Drop for Supervised<D> {
    fn drop(&mut self) {
        drop(lock(&self.shared).take());
        self.signals.close();
    }
}
