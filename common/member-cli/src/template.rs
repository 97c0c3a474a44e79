//! The member template's loop (cdm-member's `template.rs` has the protocol): read the scenario
//! once, then fork one member per request, each running the binary's own `main` with the
//! arguments it would have been started with.

use std::ffi::OsString;
use std::io::{BufRead, Write};
use std::os::unix::ffi::OsStringExt;
use std::path::Path;

use cdm_member::member::{Binary, Loaded};
use cdm_member::template::{ForkReply, ForkRequest};

use crate::{main_with, parse, print_parse_error, say};

/// Serves fork requests on stdin until it ends; returns the exit code (0, or 2 when the
/// scenario cannot be loaded, 3 when the pipes fail).
pub fn serve(scenario: &Path) -> i32 {
    let loaded = match Loaded::load(scenario) {
        Ok(l) => l,
        Err(e) => {
            say(&format!("error: member template: {e}"));
            return e.exit_code();
        }
    };
    let mut input = std::io::stdin().lock();
    let mut frame = Vec::new();
    loop {
        frame.clear();
        match input.read_until(0, &mut frame) {
            Ok(0) => return 0,
            Ok(_) => {}
            Err(e) => {
                say(&format!("error: member template: reading a request: {e}"));
                return 3;
            }
        }
        let reply = match postcard::from_bytes_cobs::<ForkRequest>(&mut frame) {
            Ok(r) => fork_one(r, &loaded),
            Err(e) => ForkReply::Failed {
                errno: None,
                why: format!("a malformed request: {e}"),
            },
        };
        let sent = postcard::to_stdvec_cobs(&reply)
            .map_err(|e| e.to_string())
            .and_then(|b| {
                let mut out = std::io::stdout().lock();
                out.write_all(&b)
                    .and_then(|()| out.flush())
                    .map_err(|e| e.to_string())
            });
        if let Err(e) = sent {
            say(&format!("error: member template: answering a request: {e}"));
            return 3;
        }
    }
}

fn fork_one(r: ForkRequest, loaded: &Loaded) -> ForkReply {
    match cdm_process::fork::fork_detached(|| member(r, loaded)) {
        Ok(pid) => ForkReply::Forked(pid),
        Err(e) => ForkReply::Failed {
            errno: e.raw_os_error(),
            why: e.to_string(),
        },
    }
}

/// The forked member: standard input and output on /dev/null (as a spawned member's), its
/// command line and name as if started from its binary, then the binary's own `main`.
fn member(r: ForkRequest, loaded: &Loaded) -> i32 {
    null_stdio();
    let binary = if r.leader {
        Binary::Leader
    } else {
        Binary::Agent
    };
    let name = binary.name();
    let args: Vec<OsString> = std::iter::once(OsString::from(name))
        .chain(r.args.into_iter().map(OsString::from_vec))
        .collect();
    // Best effort: only `ps` and tools that find a member by its arguments see them.
    let _ = cdm_process::fork::set_cmdline(&args);
    cdm_process::fork::set_name(name);
    match parse(binary, args) {
        Ok(a) => main_with(binary, a, Some(loaded)),
        Err(e) => print_parse_error(&e),
    }
}

/// Points file descriptors 0 and 1 at /dev/null (the template's are its pipes).
fn null_stdio() {
    // SAFETY: open/dup2/close on descriptors of our own; the path is NUL-terminated.
    unsafe {
        let fd = libc::open(c"/dev/null".as_ptr(), libc::O_RDWR);
        if fd >= 0 {
            libc::dup2(fd, 0);
            libc::dup2(fd, 1);
            if fd > 1 {
                libc::close(fd);
            }
        }
    }
}
