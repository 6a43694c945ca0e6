//! Which shard of the training schedules one process of an array job simulates
//! (`snapshots --shard I/N`; shard I takes every N-th schedule from I).
//!
//! Without the flag, [`Shard::from_env`] reads it from the variables the scheduler sets in each
//! process of an array:
//! - Slurm job arrays (`sbatch --array=0-7`): the index from `SLURM_ARRAY_TASK_ID` (less
//!   `SLURM_ARRAY_TASK_MIN`, divided by `SLURM_ARRAY_TASK_STEP`, where set), the count from
//!   `SLURM_ARRAY_TASK_COUNT`.
//! - Kubernetes Indexed Jobs (`completionMode: Indexed`): the index from `JOB_COMPLETION_INDEX`.
//!   Kubernetes does not pass the number of completions to the pod, so the count comes from
//!   [`SHARD_COUNT`] (`LATENT_SHARD_COUNT`), which the Job's manifest sets to its `completions`.
//!
//! `docs/cluster.md` has a batch script and a manifest.
//!
//! ```
//! use pipeline::shard::{Scheduler, Shard};
//!
//! let env = |name: &str| match name {
//!     "SLURM_ARRAY_TASK_ID" => Some("2".to_string()),
//!     "SLURM_ARRAY_TASK_COUNT" => Some("8".to_string()),
//!     _ => None,
//! };
//! let found = Shard::from_vars(env).unwrap();
//! assert_eq!(found, Some((Shard { index: 2, count: 8 }, Scheduler::Slurm)));
//! assert_eq!(Shard::from_vars(|_| None).unwrap(), None);
//! ```

/// Slurm's index of this task in its array.
pub const SLURM_ARRAY_TASK_ID: &str = "SLURM_ARRAY_TASK_ID";
/// Slurm's number of tasks in the array.
pub const SLURM_ARRAY_TASK_COUNT: &str = "SLURM_ARRAY_TASK_COUNT";
/// Slurm's first index of the array (`--array=1-8` starts at 1).
pub const SLURM_ARRAY_TASK_MIN: &str = "SLURM_ARRAY_TASK_MIN";
/// Slurm's step between indices (`--array=0-14:2`).
pub const SLURM_ARRAY_TASK_STEP: &str = "SLURM_ARRAY_TASK_STEP";
/// A Kubernetes Indexed Job's index of this pod.
pub const JOB_COMPLETION_INDEX: &str = "JOB_COMPLETION_INDEX";
/// The number of shards, for a scheduler that gives only the index (Kubernetes): set it to the
/// Job's `completions`.
pub const SHARD_COUNT: &str = "LATENT_SHARD_COUNT";

const SLURM_HINT: &str = "Slurm sets both in a job array (sbatch --array)";
const KUBERNETES_HINT: &str =
    "Kubernetes gives the pod only its index; set the count to the Job's completions";

/// Shard `index` of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// The scheduler whose variables gave a shard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheduler {
    Slurm,
    Kubernetes,
}

impl std::fmt::Display for Scheduler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Scheduler::Slurm => "Slurm job array",
            Scheduler::Kubernetes => "Kubernetes Indexed Job",
        })
    }
}

/// A shard that the flag or the environment describes wrongly.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    #[error("shard {index}/{count}: need 0 ≤ I < N")]
    OutOfRange { index: usize, count: usize },
    #[error("{variable}={value:?} is not a non-negative integer")]
    NotANumber {
        variable: &'static str,
        value: String,
    },
    #[error("{set} is set but {missing} is not: {hint}")]
    Missing {
        set: &'static str,
        missing: &'static str,
        hint: &'static str,
    },
    #[error(
        "{SLURM_ARRAY_TASK_ID}={id} is not in the array that {SLURM_ARRAY_TASK_MIN}={min}, \
         {SLURM_ARRAY_TASK_STEP}={step} and {SLURM_ARRAY_TASK_COUNT}={count} describe"
    )]
    NotInArray {
        id: usize,
        min: usize,
        step: usize,
        count: usize,
    },
    #[error(
        "both {SLURM_ARRAY_TASK_ID} and {JOB_COMPLETION_INDEX} are set: unset the one of the \
         scheduler that does not run this process, or pass --shard I/N"
    )]
    TwoSchedulers,
}

impl Shard {
    /// Shard `index` of `count`, checked.
    pub fn new(index: usize, count: usize) -> Result<Self, ShardError> {
        if index < count {
            Ok(Self { index, count })
        } else {
            Err(ShardError::OutOfRange { index, count })
        }
    }

    /// The shard this process's array-job variables give (module docs), `None` when none of
    /// them is set.
    pub fn from_env() -> Result<Option<(Self, Scheduler)>, ShardError> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    /// [`Shard::from_env`] with the variables looked up by `var`.
    pub fn from_vars(
        var: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<(Self, Scheduler)>, ShardError> {
        let number = |variable: &'static str| -> Result<Option<usize>, ShardError> {
            var(variable)
                .map(|value| {
                    value.trim().parse().map_err(|_| ShardError::NotANumber {
                        variable,
                        value: value.clone(),
                    })
                })
                .transpose()
        };
        let missing = |set, missing, hint| ShardError::Missing { set, missing, hint };
        // The count that must come with the index variable `set`.
        let count_beside = |set, count, hint| number(count)?.ok_or(missing(set, count, hint));
        if var(SLURM_ARRAY_TASK_ID).is_some() && var(JOB_COMPLETION_INDEX).is_some() {
            return Err(ShardError::TwoSchedulers);
        }
        if let Some(id) = number(SLURM_ARRAY_TASK_ID)? {
            let count = count_beside(SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT, SLURM_HINT)?;
            let min = number(SLURM_ARRAY_TASK_MIN)?.unwrap_or(0);
            let step = number(SLURM_ARRAY_TASK_STEP)?.unwrap_or(1).max(1);
            let offset = id.checked_sub(min).filter(|o| o % step == 0);
            let shard = offset.and_then(|o| Self::new(o / step, count).ok());
            return shard
                .map(|s| Some((s, Scheduler::Slurm)))
                .ok_or(ShardError::NotInArray {
                    id,
                    min,
                    step,
                    count,
                });
        }
        if let Some(index) = number(JOB_COMPLETION_INDEX)? {
            let count = count_beside(JOB_COMPLETION_INDEX, SHARD_COUNT, KUBERNETES_HINT)?;
            return Self::new(index, count).map(|s| Some((s, Scheduler::Kubernetes)));
        }
        // A count alone does not say which shard this process simulates.
        for (count, index) in [
            (SHARD_COUNT, JOB_COMPLETION_INDEX),
            (SLURM_ARRAY_TASK_COUNT, SLURM_ARRAY_TASK_ID),
        ] {
            if var(count).is_some() {
                return Err(missing(
                    count,
                    index,
                    "the count alone does not say which shard this process simulates",
                ));
            }
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from(vars: &[(&str, &str)]) -> Result<Option<(Shard, Scheduler)>, ShardError> {
        Shard::from_vars(|name| {
            vars.iter()
                .find(|(n, _)| *n == name)
                .map(|(_, v)| v.to_string())
        })
    }

    fn shard(index: usize, count: usize, scheduler: Scheduler) -> Option<(Shard, Scheduler)> {
        Some((Shard { index, count }, scheduler))
    }

    #[test]
    fn slurm_arrays_give_the_index_from_their_first_task_and_step() {
        use Scheduler::Slurm;
        let slurm = |id, extra: &[(&str, &str)]| {
            let mut vars = vec![(SLURM_ARRAY_TASK_ID, id), (SLURM_ARRAY_TASK_COUNT, "4")];
            vars.extend_from_slice(extra);
            from(&vars)
        };
        assert_eq!(slurm("0", &[]), Ok(shard(0, 4, Slurm)));
        assert_eq!(slurm(" 3\n", &[]), Ok(shard(3, 4, Slurm)));
        // --array=1-4
        assert_eq!(
            slurm("4", &[(SLURM_ARRAY_TASK_MIN, "1")]),
            Ok(shard(3, 4, Slurm))
        );
        // --array=10-16:2
        let stepped = [(SLURM_ARRAY_TASK_MIN, "10"), (SLURM_ARRAY_TASK_STEP, "2")];
        assert_eq!(slurm("14", &stepped), Ok(shard(2, 4, Slurm)));
        for outside in ["15", "8", "18"] {
            assert!(
                matches!(slurm(outside, &stepped), Err(ShardError::NotInArray { .. })),
                "{outside}"
            );
        }
        assert!(matches!(
            slurm("4", &[]),
            Err(ShardError::NotInArray { .. })
        ));
        assert_eq!(
            from(&[(SLURM_ARRAY_TASK_ID, "1")]),
            Err(ShardError::Missing {
                set: SLURM_ARRAY_TASK_ID,
                missing: SLURM_ARRAY_TASK_COUNT,
                hint: SLURM_HINT,
            })
        );
        assert!(matches!(
            slurm("one", &[]),
            Err(ShardError::NotANumber {
                variable: SLURM_ARRAY_TASK_ID,
                ..
            })
        ));
        // The count alone (left in the environment of a process outside the array).
        let err = from(&[(SLURM_ARRAY_TASK_COUNT, "8")]).unwrap_err();
        assert!(err.to_string().contains(SLURM_ARRAY_TASK_ID), "{err}");
    }

    #[test]
    fn kubernetes_indexed_jobs_need_the_count_beside_the_index() {
        use Scheduler::Kubernetes;
        let k8s = [(JOB_COMPLETION_INDEX, "5"), (SHARD_COUNT, "6")];
        assert_eq!(from(&k8s), Ok(shard(5, 6, Kubernetes)));
        assert_eq!(
            from(&[(JOB_COMPLETION_INDEX, "6"), (SHARD_COUNT, "6")]),
            Err(ShardError::OutOfRange { index: 6, count: 6 })
        );
        let err = from(&[(JOB_COMPLETION_INDEX, "0")]).unwrap_err();
        assert!(err.to_string().contains(SHARD_COUNT), "{err}");
        let err = from(&[(SHARD_COUNT, "6")]).unwrap_err();
        assert!(err.to_string().contains(JOB_COMPLETION_INDEX), "{err}");
        assert_eq!(
            from(&[(JOB_COMPLETION_INDEX, "1"), (SHARD_COUNT, "-2")]),
            Err(ShardError::NotANumber {
                variable: SHARD_COUNT,
                value: "-2".into()
            })
        );
        // Two schedulers' indices: which one runs this process is not guessed.
        let both = [
            (JOB_COMPLETION_INDEX, "1"),
            (SHARD_COUNT, "2"),
            (SLURM_ARRAY_TASK_ID, "0"),
            (SLURM_ARRAY_TASK_COUNT, "3"),
        ];
        assert_eq!(from(&both), Err(ShardError::TwoSchedulers));
    }

    #[test]
    fn no_array_variable_is_no_shard() {
        assert_eq!(from(&[("SLURM_JOB_ID", "77")]), Ok(None));
        assert_eq!(
            Shard::new(0, 0),
            Err(ShardError::OutOfRange { index: 0, count: 0 })
        );
    }
}
