//! Opening a study in the background: load, preprocess, build what the window needs, while
//! the window stays responsive and shows the progress.

use std::{
    sync::mpsc::{Receiver, TryRecvError, channel},
    thread,
};

use anyhow::Context as _;
use voyage_io as io;
use voyage_phantom::{self as phantom, ColonOptions};

use super::session::Session;
use crate::open::{
    Choices, InputArgs, OPEN_STEPS, Opening, PointArgs, exam_of, open_study, prepare_volume,
};

/// What to open.
#[derive(Clone, Debug)]
pub enum Source {
    /// A CT (DICOM folder or file, NIfTI, MetaImage, NRRD) or a lumen mask, with the
    /// user's choices, as the commands take it.
    File(InputArgs),
    /// The built-in colon phantom, made on the fly.
    Phantom { small: bool, points: PointArgs },
}

impl Source {
    pub fn describe(&self) -> String {
        match self {
            Source::File(a) => a.input.display().to_string(),
            Source::Phantom { small: false, .. } => "the colon phantom".into(),
            Source::Phantom { small: true, .. } => "the small colon phantom".into(),
        }
    }

    /// The user's choices of points (seeds, exclusions, ends) and position.
    pub fn points(&self) -> &PointArgs {
        match self {
            Source::File(InputArgs { points, .. }) | Source::Phantom { points, .. } => points,
        }
    }

    /// The same input with other points.
    pub fn with_points(&self, points: PointArgs) -> Source {
        let mut s = self.clone();
        match &mut s {
            Source::File(InputArgs { points: p, .. }) | Source::Phantom { points: p, .. } => {
                *p = points
            }
        }
        s
    }
}

enum Message {
    Progress {
        step: usize,
        of: usize,
        what: String,
    },
    Done(Box<anyhow::Result<Session>>),
}

/// A study being opened.
pub struct Job {
    pub source: Source,
    rx: Receiver<Message>,
    pub step: usize,
    pub of: usize,
    pub what: String,
    pub started: std::time::Instant,
}

/// Steps a job takes beyond opening ([`OPEN_STEPS`]: reading or making the phantom, the
/// preprocessing stages): setting up navigation and rendering.
const EXTRA_STEPS: usize = 1;

impl Job {
    pub fn start(source: Source, ctx: egui::Context) -> Job {
        let (tx, rx) = channel();
        let src = source.clone();
        thread::Builder::new()
            .name("voyage-open".into())
            .spawn(move || {
                let progress = |step: usize, what: &str| {
                    let _ = tx.send(Message::Progress {
                        step,
                        of: OPEN_STEPS + EXTRA_STEPS,
                        what: what.to_string(),
                    });
                    ctx.request_repaint();
                };
                let result = open(&src, &progress);
                let _ = tx.send(Message::Done(Box::new(result)));
                ctx.request_repaint();
            })
            .expect("spawning a thread");
        Job {
            source,
            rx,
            step: 0,
            of: OPEN_STEPS + EXTRA_STEPS,
            what: "starting".into(),
            started: std::time::Instant::now(),
        }
    }

    /// The session when it is ready (Some(Err) when opening failed), None while working.
    pub fn poll(&mut self) -> Option<anyhow::Result<Session>> {
        loop {
            match self.rx.try_recv() {
                Ok(Message::Progress { step, of, what }) => {
                    (self.step, self.of, self.what) = (step, of, what)
                }
                Ok(Message::Done(r)) => return Some(*r),
                Err(TryRecvError::Empty) => return None,
                Err(TryRecvError::Disconnected) => {
                    return Some(Err(anyhow::anyhow!(
                        "{}: opening stopped unexpectedly",
                        self.source.describe()
                    )));
                }
            }
        }
    }

    pub fn fraction(&self) -> f32 {
        self.step as f32 / self.of.max(1) as f32
    }
}

fn open(source: &Source, progress: &dyn Fn(usize, &str)) -> anyhow::Result<Session> {
    let tell = |o: Opening| progress(o.step, o.what);
    let (study, exam) = match source {
        Source::File(input) => {
            let p = open_study(input, None, tell)?;
            (p.study, p.exam)
        }
        Source::Phantom { small, points } => {
            progress(0, "making the colon phantom");
            let ct = phantom::colon(&ColonOptions {
                small: *small,
                ..ColonOptions::default()
            })?
            .ct;
            let choices = Choices {
                points,
                mask: false,
                nav_min_wall_mm: None,
            };
            let meta = io::Meta::default();
            let exam = exam_of("colon phantom", &meta, points, ct.geometry());
            let study = prepare_volume(ct, meta, &choices, &source.describe(), tell)?;
            (study, exam)
        }
    };
    progress(OPEN_STEPS, "setting up the flight");
    Session::new(exam, study).with_context(|| source.describe())
}
