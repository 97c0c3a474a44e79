//! Members forked from the member template (cdm-member's `template.rs`) instead of started from
//! their binary one by one: the orchestrator's side. The template reads the scenario once; each
//! member is forked from it with the arguments it would have been started with and becomes the
//! orchestrator's child (this process turns subreaper, `cdm_process::fork`), watched and
//! stopped like a started one ([`MemberProcess`]).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::ffi::OsStringExt;
use std::os::unix::io::AsRawFd;
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::time::Duration;

use cdm_iox::TeamName;
use cdm_member::template::{ForkReply, ForkRequest, FLAG};
use cdm_model::formation::Role;

use crate::team::{member_args, MemberProcess};

/// How long a fork may take before the template is considered stuck.
const REPLY_DEADLINE: Duration = Duration::from_secs(10);

/// Bytes of command line the template is started with, so that each forked member can show
/// its own arguments in that room (`cdm_process::fork::set_cmdline`).
const CMDLINE_ROOM: usize = 4096;

/// The running member template.
pub struct MemberTemplate {
    child: Child,
    to: ChildStdin,
    from: BufReader<ChildStdout>,
}

impl MemberTemplate {
    /// Starts the template (the `agent` binary beside this one) on `scenario`, the members'
    /// scenario file, and makes this process the subreaper of the members it will fork.
    pub fn start(scenario: &Path) -> std::io::Result<Self> {
        cdm_process::fork::become_subreaper()?;
        let exe = std::env::current_exe()?.with_file_name("agent");
        let mut child = Command::new(exe)
            .arg(FLAG)
            .arg(scenario)
            .arg(".".repeat(CMDLINE_ROOM))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()?;
        let (Some(to), Some(from)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(std::io::Error::other("the member template has no pipes"));
        };
        Ok(MemberTemplate {
            child,
            to,
            from: BufReader::new(from),
        })
    }

    /// Forks member `id` as `spawn_member` would start it (the same arguments).
    pub fn fork(
        &mut self,
        scenario: &Path,
        team: &TeamName,
        (id, role): (u32, Role),
        flags: &[String],
    ) -> std::io::Result<MemberProcess> {
        let request = ForkRequest {
            leader: role.is_leader(),
            args: member_args(scenario, team, id, flags)
                .into_iter()
                .map(OsStringExt::into_vec)
                .collect(),
        };
        let frame = postcard::to_stdvec_cobs(&request).map_err(std::io::Error::other)?;
        self.to.write_all(&frame)?;
        self.to.flush()?;
        let mut reply = self.read_frame()?;
        match postcard::from_bytes_cobs::<ForkReply>(&mut reply) {
            Ok(ForkReply::Forked(pid)) => {
                Ok(MemberProcess::Forked(cdm_process::fork::Adopted::new(pid)))
            }
            // The OS's own error, so that the process limit is explained as for a spawn.
            Ok(ForkReply::Failed {
                errno: Some(errno), ..
            }) => Err(std::io::Error::from_raw_os_error(errno)),
            Ok(ForkReply::Failed { why, .. }) => Err(std::io::Error::other(format!(
                "the member template could not fork it: {why}"
            ))),
            Err(e) => Err(std::io::Error::other(format!(
                "the member template answered a malformed reply: {e}"
            ))),
        }
    }

    /// The next reply frame, within [`REPLY_DEADLINE`].
    fn read_frame(&mut self) -> std::io::Result<Vec<u8>> {
        if self.from.buffer().is_empty() {
            let mut fd = libc::pollfd {
                fd: self.from.get_ref().as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            };
            let ms = REPLY_DEADLINE.as_millis() as libc::c_int;
            // SAFETY: poll reads and writes the one pollfd we own.
            let ready = unsafe { libc::poll(&mut fd, 1, ms) };
            if ready == 0 {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    format!(
                        "the member template did not answer within {} s",
                        REPLY_DEADLINE.as_secs()
                    ),
                ));
            }
            if ready < 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
        let mut frame = Vec::new();
        self.from.read_until(0, &mut frame)?;
        if frame.last() != Some(&0) {
            let how = self
                .child
                .try_wait()
                .ok()
                .flatten()
                .map_or("closed its output".to_string(), |s| s.to_string());
            return Err(std::io::Error::other(format!(
                "the member template stopped answering ({how})"
            )));
        }
        Ok(frame)
    }

    /// Ends the template (the end of its input) and reaps it; killed if it has not ended
    /// within a second.
    pub fn finish(self) {
        let MemberTemplate { mut child, to, .. } = self;
        drop(to);
        let until = std::time::Instant::now() + Duration::from_secs(1);
        while matches!(child.try_wait(), Ok(None)) && std::time::Instant::now() < until {
            std::thread::sleep(Duration::from_millis(2));
        }
        if matches!(child.try_wait(), Ok(None)) {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}
