//! Stage times of a rank: wall time, and the CPU time of the rank's own thread. When a rank
//! runs on one thread (as `aarbf bench distributed` runs each, so that ranks oversubscribing
//! a few cores still time their own work), its thread's CPU time is its work alone: a rank
//! waiting in a collective sleeps and is not charged, and another rank's work on the same
//! core is not counted.

use std::time::Instant;

/// A stage's clock, started at [`StageClock::start`].
pub(crate) struct StageClock {
    wall: Instant,
    cpu: Option<f64>,
}

impl StageClock {
    /// Starts timing a stage.
    pub(crate) fn start() -> StageClock {
        StageClock {
            wall: Instant::now(),
            cpu: thread_cpu_seconds(),
        }
    }

    /// Seconds since the start: wall time, then the calling thread's CPU time (the wall time
    /// where the system has no per-thread CPU clock).
    pub(crate) fn stop(&self) -> (f64, f64) {
        let wall = self.wall.elapsed().as_secs_f64();
        let cpu = match (self.cpu, thread_cpu_seconds()) {
            (Some(a), Some(b)) => b - a,
            _ => wall,
        };
        (wall, cpu)
    }
}

/// The calling thread's CPU time in seconds (Linux: `CLOCK_THREAD_CPUTIME_ID`).
#[cfg(target_os = "linux")]
fn thread_cpu_seconds() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant the kernel knows.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
}

/// The calling thread's CPU time: not measured on this system.
#[cfg(not(target_os = "linux"))]
fn thread_cpu_seconds() -> Option<f64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Busy work is charged to the thread; sleeping (as in a collective's wait) is not.
    #[test]
    fn a_sleeping_thread_is_not_charged() {
        let clock = StageClock::start();
        std::thread::sleep(std::time::Duration::from_millis(60));
        let (wall, cpu) = clock.stop();
        assert!(wall >= 0.06, "{wall}");
        assert!(cpu < 0.03, "slept 60 ms, charged {cpu} s");

        // Busy until the thread has run 30 ms of CPU (bounded, on a loaded machine, by 10 s).
        let clock = StageClock::start();
        let mut x = 0u64;
        while clock.stop().1 < 0.03 && clock.wall.elapsed().as_secs_f64() < 10.0 {
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        }
        let (wall, cpu) = clock.stop();
        assert!(
            (0.03..=wall + 0.005).contains(&cpu),
            "busy {wall} s, charged {cpu} s"
        );
    }
}
