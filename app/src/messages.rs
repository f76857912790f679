//! The session's messages: every status and error message with its time, bounded, for the
//! message panel (`views::messages`). Whoever sets `AppState::status` gets the message listed
//! (see [`Messages::sync`]); errors that never reach the status line are pushed directly.

use std::collections::VecDeque;
use std::time::{SystemTime, UNIX_EPOCH};

/// How many messages are kept (the oldest go first).
pub const MAX_MESSAGES: usize = 200;

/// How serious a message is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Something done or under way.
    Info,
    /// Something that failed or was refused.
    Error,
}

/// One message: when (s since the Unix epoch), how serious, what.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// Time it was noted (s since 1970-01-01 UTC).
    pub time_s: f64,
    /// Its level.
    pub level: Level,
    /// The text.
    pub text: String,
}

/// The recent messages and whether the panel is open.
#[derive(Debug, Default)]
pub struct Messages {
    /// Oldest first, at most [`MAX_MESSAGES`].
    pub list: VecDeque<Message>,
    /// The panel is shown.
    pub open: bool,
    /// The status text last listed, so a status set anywhere is listed once.
    last_status: String,
}

/// Words that make a status line an error.
const ERROR_WORDS: [&str; 7] = ["failed", "cannot", "NOT ", "refused", "error", "not changed", "lost"];

impl Messages {
    /// Add a message now.
    pub fn push(&mut self, level: Level, text: impl Into<String>) {
        let time_s = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64());
        self.list.push_back(Message { time_s, level, text: text.into() });
        while self.list.len() > MAX_MESSAGES {
            self.list.pop_front();
        }
    }

    /// List the status line if it changed since last listed; a status that says something
    /// failed, was refused or cannot be done is an error.
    pub fn sync(&mut self, status: &str) {
        if status.is_empty() || status == self.last_status {
            return;
        }
        self.last_status = status.to_string();
        let level = if ERROR_WORDS.iter().any(|w| status.contains(w)) { Level::Error } else { Level::Info };
        self.push(level, status);
    }

    /// How many errors are listed.
    pub fn errors(&self) -> usize {
        self.list.iter().filter(|m| m.level == Level::Error).count()
    }
}

/// `HH:MM:SS` UTC of a time (s since the Unix epoch).
pub fn clock_utc(time_s: f64) -> String {
    let s = time_s.max(0.0) as u64 % 86_400;
    format!("{:02}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_list_keeps_every_new_status_once_classifies_errors_and_is_bounded() {
        let mut m = Messages::default();
        m.sync("");
        m.sync("opened /tmp/s");
        m.sync("opened /tmp/s");
        m.sync("cannot open: no session.ron");
        assert_eq!(m.list.len(), 2, "an unchanged status is listed once");
        assert_eq!((m.list[0].level, m.list[1].level), (Level::Info, Level::Error));
        for k in 0..(MAX_MESSAGES + 10) {
            m.push(Level::Info, format!("message {k}"));
        }
        assert_eq!(m.list.len(), MAX_MESSAGES);
        assert_eq!(m.list.back().unwrap().text, format!("message {}", MAX_MESSAGES + 9));
        assert_eq!(clock_utc(86_400.0 * 3.0 + 3661.0), "01:01:01");
    }
}
