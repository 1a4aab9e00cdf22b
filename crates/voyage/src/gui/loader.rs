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
    Choices, InputArgs, OPEN_STEPS, Opening, PointArgs, exam_of, open_exam, prepare_volume,
};

/// What to open.
#[derive(Clone, Debug)]
pub enum Source {
    /// A CT (DICOM folder or file, NIfTI, MetaImage, NRRD) or a lumen mask, with the
    /// user's choices, as the commands take it.
    File(InputArgs),
    /// The built-in colon phantom, made on the fly; `pair`: supine and prone, with tagged
    /// fluid and stool (`voyage phantom colon --pair`).
    Phantom {
        small: bool,
        pair: bool,
        points: PointArgs,
    },
}

impl Source {
    pub fn describe(&self) -> String {
        match self {
            Source::File(a) => a.input.display().to_string(),
            Source::Phantom {
                small, pair: true, ..
            } => format!(
                "the {}colon phantom supine and prone",
                if *small { "small " } else { "" }
            ),
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

    /// The same input, its series `uid` (one position of an exam) when it is a file.
    pub fn with_series(&self, uid: Option<String>) -> Source {
        let mut s = self.clone();
        if let Source::File(a) = &mut s {
            a.series = uid;
        }
        s
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
    Done(Box<anyhow::Result<Vec<Session>>>),
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
                let progress = |step: usize, of: usize, what: &str| {
                    let _ = tx.send(Message::Progress {
                        step,
                        of,
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

    /// The sessions when they are ready, one per position of the exam, the first shown
    /// (Some(Err) when opening failed), None while working.
    pub fn poll(&mut self) -> Option<anyhow::Result<Vec<Session>>> {
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

fn open(source: &Source, progress: &dyn Fn(usize, usize, &str)) -> anyhow::Result<Vec<Session>> {
    let one = OPEN_STEPS + EXTRA_STEPS;
    let opened: Vec<(voyage_core::Study, voyage_export::Exam, Option<String>)> = match source {
        Source::File(input) => {
            // Every position of the exam, one after another: the steps of all of them.
            open_exam(input, None, |i, n, o| {
                let of = n * OPEN_STEPS + EXTRA_STEPS;
                let what = if n > 1 {
                    format!("position {} of {n}: {}", i + 1, o.what)
                } else {
                    o.what.to_string()
                };
                progress(i * OPEN_STEPS + o.step, of, &what)
            })?
            .into_iter()
            .map(|p| (p.study, p.exam, p.series_uid))
            .collect()
        }
        Source::Phantom {
            small,
            pair,
            points,
        } => {
            // (CT, what the loader would have found, exam name, name in errors).
            let made: Vec<(voyage_core::Volume<i16>, io::Meta, String, String)> = if *pair {
                progress(
                    0,
                    2 * OPEN_STEPS + EXTRA_STEPS,
                    "making the colon phantom supine and prone",
                );
                let pair = phantom::pair::colon_pair(&ColonOptions {
                    small: *small,
                    tagged_fluid: true,
                    tagged_stool: true,
                    ..ColonOptions::default()
                })?;
                [(pair.supine, "supine"), (pair.prone, "prone")]
                    .into_iter()
                    .map(|(p, position)| {
                        // As the phantom's DICOM series say it.
                        let meta = io::Meta {
                            position: voyage_core::PatientPosition::parse(&p.truth.position),
                            ..Default::default()
                        };
                        let name = format!("colon phantom ({position})");
                        (p.ct, meta, name.clone(), name)
                    })
                    .collect()
            } else {
                progress(0, one, "making the colon phantom");
                let ct = phantom::colon(&ColonOptions {
                    small: *small,
                    ..ColonOptions::default()
                })?
                .ct;
                vec![(
                    ct,
                    io::Meta::default(),
                    "colon phantom".into(),
                    source.describe(),
                )]
            };
            let choices = Choices {
                points,
                mask: false,
                nav_min_wall_mm: None,
            };
            let of = made.len() * OPEN_STEPS + EXTRA_STEPS;
            let mut opened = Vec::new();
            for (i, (ct, meta, name, what)) in made.into_iter().enumerate() {
                let exam = exam_of(&name, &meta, points, ct.geometry());
                let tell = |o: Opening| progress(i * OPEN_STEPS + o.step, of, o.what);
                let study = prepare_volume(ct, meta, &choices, &what, tell)?;
                opened.push((study, exam, None));
            }
            opened
        }
    };
    let n = opened.len();
    progress(
        n * OPEN_STEPS,
        n * OPEN_STEPS + EXTRA_STEPS,
        "setting up the flight",
    );
    opened
        .into_iter()
        .map(|(study, exam, series_uid)| {
            let mut s = Session::new(exam, study).with_context(|| source.describe())?;
            s.series_uid = series_uid;
            s.points = source.points().clone();
            Ok(s)
        })
        .collect()
}
