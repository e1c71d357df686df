//! One error type for the libraries. The binary turns it into a message for people and an
//! exit code: 2 for input the user must fix, 1 for a failure while running.

use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A mesh file that cannot be used: names the file and the problem.
    #[error("mesh {path}: {problem}")]
    Mesh { path: PathBuf, problem: String },

    /// Any other input the user must change (a parameter out of range, a bad argument).
    #[error("{0}")]
    Invalid(String),

    /// A request refused before allocating because it would not fit in memory.
    #[error(
        "{what} would need {} but this machine has {} available; lower the resolution or the size",
        human_bytes(*needed), human_bytes(*available)
    )]
    TooLarge {
        what: String,
        needed: u64,
        available: u64,
    },

    /// A numerical failure while running: names the stage, the frame and what to change.
    #[error("node '{node}', frame {frame}: {message} (try: {hint})")]
    Numerical {
        node: String,
        frame: u32,
        message: String,
        hint: String,
    },

    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// No usable GPU, or a GPU operation that failed.
    #[error("GPU: {0}")]
    Gpu(String),

    /// Anything else that went wrong while running.
    #[error("{0}")]
    Run(String),

    /// Stopped by a signal (Ctrl-C, SIGTERM) after `frame`'s predecessor; exit code 130.
    #[error("interrupted before frame {frame}")]
    Interrupted { frame: u32 },
}

impl Error {
    /// 2: the input is invalid (fix the file or the arguments); 1: a failure while running;
    /// 130: interrupted (the shells' code for Ctrl-C).
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Mesh { .. } | Error::Invalid(_) | Error::TooLarge { .. } => 2,
            Error::Interrupted { .. } => 130,
            _ => 1,
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    pub fn mesh(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Error::Mesh {
            path: path.into(),
            problem: problem.into(),
        }
    }
}

/// `1.5 GiB`-style sizes for messages.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 6] = ["B", "KiB", "MiB", "GiB", "TiB", "PiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// Memory the OS says is available (MemAvailable), or a conservative 4 GiB where unknown.
pub fn available_memory() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
                .map(|kb| kb * 1024)
        })
        .unwrap_or(4 << 30)
}

/// Refuses, before allocating, a request of `needed` bytes that would not fit in memory.
pub fn check_alloc(what: &str, needed: u64) -> Result<()> {
    let available = available_memory();
    if needed > available {
        return Err(Error::TooLarge {
            what: what.to_string(),
            needed,
            available,
        });
    }
    Ok(())
}
