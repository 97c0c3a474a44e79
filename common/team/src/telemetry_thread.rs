//! A telemetry sink on its own thread, for `launch`: the orchestrator's loop hands each
//! complete tick's rows over and goes on receiving and granting, while the writer thread makes
//! the text (or Parquet) and writes it. At N = 40 the CSV text was about three quarters of the
//! orchestrator's CPU and a fifth of the whole team's (perf), all of it on the loop
//! that the members wait for. The file is the same, byte for byte: one writer, the ticks in
//! the order they were handed over.
//!
//! The queue is bounded (about 65,536 rows): when the writer falls behind, the loop waits for
//! it instead of growing without limit. A write that fails (a full disk) is returned by the next
//! call after it (`write_tick`, `flush` or `finish`); the writer then drops the ticks still
//! queued, and the file keeps its whole ticks as the sink keeps them on its own.

use std::io;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use cdm_records::telemetry::{Row, TelemetrySink};

/// Rows queued at most (whole ticks; at least [`MIN_TICKS`] of them).
const QUEUE_ROWS: usize = 1 << 16;
/// Ticks queued at least, whatever the team's size.
const MIN_TICKS: usize = 4;

enum Job {
    Tick(Vec<Row>),
    Flush,
}

/// The sink's side in the orchestrator's loop.
pub struct ThreadedSink {
    every: u64,
    jobs: Option<SyncSender<Job>>,
    /// Emptied row buffers coming back, so a tick costs no allocation.
    spare: Receiver<Vec<Row>>,
    failed: Arc<Mutex<Option<io::Error>>>,
    writer: Option<JoinHandle<io::Result<()>>>,
}

impl ThreadedSink {
    /// Moves `sink` (keeping every `every`-th tick) to a writer thread; `members`: rows per tick.
    pub fn start(
        sink: Box<dyn TelemetrySink + Send>,
        every: u64,
        members: usize,
    ) -> io::Result<Self> {
        let ticks = (QUEUE_ROWS / members.max(1)).max(MIN_TICKS);
        let (jobs, queue) = sync_channel(ticks);
        let (give_back, spare) = sync_channel(ticks);
        let failed = Arc::new(Mutex::new(None));
        let seen = Arc::clone(&failed);
        let writer = std::thread::Builder::new()
            .name("telemetry".into())
            .spawn(move || write_all(sink, &queue, &give_back, &seen))?;
        Ok(ThreadedSink {
            every: every.max(1),
            jobs: Some(jobs),
            spare,
            failed,
            writer: Some(writer),
        })
    }

    /// The writer's failure, once (later calls report it again, as a copy).
    fn failure(&self) -> io::Result<()> {
        match &*self.failed.lock().unwrap_or_else(|p| p.into_inner()) {
            Some(e) => Err(io::Error::new(e.kind(), e.to_string())),
            None => Ok(()),
        }
    }

    fn send(&mut self, job: Job) -> io::Result<()> {
        self.failure()?;
        let sent = self.jobs.as_ref().map(|j| j.send(job));
        match sent {
            Some(Ok(())) => Ok(()),
            // The writer ended: its failure says why (or it panicked).
            _ => self
                .failure()
                .and(Err(io::Error::other("the telemetry writer stopped"))),
        }
    }

    /// Waits for the writer to write everything queued; its result.
    fn join(&mut self) -> io::Result<()> {
        drop(self.jobs.take());
        let ended = match self.writer.take() {
            Some(w) => w
                .join()
                .unwrap_or_else(|_| Err(io::Error::other("the telemetry writer panicked"))),
            None => Ok(()),
        };
        self.failure().and(ended)
    }
}

/// The writer thread: every tick in order, flushes when asked, and the end of the file once the
/// loop's side is gone. After a failure it keeps receiving (so the loop never blocks on a full
/// queue) but writes nothing more.
fn write_all(
    mut sink: Box<dyn TelemetrySink + Send>,
    queue: &Receiver<Job>,
    give_back: &SyncSender<Vec<Row>>,
    failed: &Mutex<Option<io::Error>>,
) -> io::Result<()> {
    let mut ok = true;
    while let Ok(job) = queue.recv() {
        let done = match job {
            Job::Tick(mut rows) if ok => {
                let r = sink.write_tick(&rows);
                rows.clear();
                let _ = give_back.try_send(rows);
                r
            }
            Job::Flush if ok => sink.flush(),
            _ => Ok(()),
        };
        if let Err(e) = done {
            ok = false;
            *failed.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
        }
    }
    if ok {
        sink.finish()
    } else {
        Ok(())
    }
}

impl TelemetrySink for ThreadedSink {
    fn keeps(&self, tick: u64) -> bool {
        tick.is_multiple_of(self.every)
    }

    fn write_tick(&mut self, rows: &[Row]) -> io::Result<()> {
        let mut buf = match self.spare.try_recv() {
            Ok(b) => b,
            Err(TryRecvError::Empty | TryRecvError::Disconnected) => Vec::with_capacity(rows.len()),
        };
        buf.extend_from_slice(rows);
        self.send(Job::Tick(buf))
    }

    /// Asks the writer to flush what it has written so far; does not wait for it.
    fn flush(&mut self) -> io::Result<()> {
        self.send(Job::Flush)
    }

    fn finish(&mut self) -> io::Result<()> {
        self.join()
    }
}

/// Dropped on any path (a fault, an interrupt): the writer still writes every tick queued and
/// ends the file (best effort), as the sink would on its own.
impl Drop for ThreadedSink {
    fn drop(&mut self) {
        let _ = self.join();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_records::telemetry::{Rewind, TelemetryWriter};

    fn row(tick: u64, id: u32) -> Row {
        Row {
            tick,
            t_s: tick as f64 * 0.01,
            id,
            role: cdm_model::formation::Role::Follower,
            r: cdm_math::Vec3::new(1.0, 2.0, 3.0),
            v: cdm_math::Vec3::zeros(),
            ht: cdm_math::Vec3::new(0.1, 0.2, 0.3),
        }
    }

    /// A shared in-memory file, so the test reads what the writer thread wrote.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);
    impl io::Write for Shared {
        fn write(&mut self, b: &[u8]) -> io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }
    impl Rewind for Shared {
        fn rewind_to(&mut self, len: u64) -> io::Result<()> {
            self.0.lock().unwrap().truncate(len as usize);
            Ok(())
        }
    }

    #[test]
    fn the_file_is_the_one_the_sink_writes_on_its_own() {
        let ticks: Vec<Vec<Row>> = (0..50u64)
            .map(|t| (1..=7).map(|id| row(t, id)).collect())
            .collect();
        let direct_file = Shared::default();
        let mut direct = TelemetryWriter::new(direct_file.clone(), 3).unwrap();
        let threaded_file = Shared::default();
        let inner = TelemetryWriter::new(threaded_file.clone(), 3).unwrap();
        let mut threaded = ThreadedSink::start(Box::new(inner), 3, 7).unwrap();
        for rows in &ticks {
            assert_eq!(threaded.keeps(rows[0].tick), direct.keeps(rows[0].tick));
            if direct.keeps(rows[0].tick) {
                direct.write_tick(rows).unwrap();
                threaded.write_tick(rows).unwrap();
            }
            if rows[0].tick % 10 == 0 {
                threaded.flush().unwrap();
            }
        }
        direct.finish().unwrap();
        threaded.finish().unwrap();
        let direct_bytes = direct_file.0.lock().unwrap().clone();
        assert!(direct_bytes.len() > 1000);
        assert_eq!(*threaded_file.0.lock().unwrap(), direct_bytes);
    }

    /// A sink whose writes fail from the third tick on.
    struct Failing(u32);
    impl TelemetrySink for Failing {
        fn keeps(&self, _: u64) -> bool {
            true
        }
        fn write_tick(&mut self, _: &[Row]) -> io::Result<()> {
            self.0 += 1;
            if self.0 >= 3 {
                return Err(io::Error::new(io::ErrorKind::StorageFull, "disk full"));
            }
            Ok(())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
        fn finish(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_failed_write_comes_back_by_a_later_call_and_at_the_end() {
        // A team this large gets the shortest queue (MIN_TICKS = 4 ticks), so the loop cannot
        // run ahead of the writer: once the send of tick 7 returns, the writer has taken tick 3,
        // so it has failed on tick 2, whatever the scheduler did. (With a long queue the loop
        // could hand over every tick before the writer ran at all.)
        let mut t = ThreadedSink::start(Box::new(Failing(0)), 1, QUEUE_ROWS).unwrap();
        let mut first_error = None;
        for tick in 0..1000 {
            if let Err(e) = t.write_tick(&[row(tick, 1)]) {
                first_error = Some((tick, e));
                break;
            }
        }
        let (tick, e) = first_error.expect("the failure came back");
        assert!(
            tick <= 8,
            "the failure of tick 2 came back only at tick {tick}"
        );
        assert_eq!(e.kind(), io::ErrorKind::StorageFull);
        assert_eq!(t.finish().unwrap_err().kind(), io::ErrorKind::StorageFull);
    }
}
