//! The methods a report tells apart: the algorithms, and SAC's two published critic-ensemble
//! variants, named from a run's settings ([`Method::of`]): DroQ (dropout in the critics) and REDQ
//! (a random subset of the critics in each target). Each is a column of Table 1 of its own.

use serde::Serialize;

use crate::agent::Algo;
use crate::config::Config;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Sac,
    /// SAC with `agent.sac.critic_dropout > 0` (Hiraoka et al., ICLR 2022).
    Droq,
    /// SAC with `agent.sac.critic_subset` below `n_critics` (Chen et al., ICLR 2021).
    Redq,
    Ddpg,
    Td3,
    Ppo,
    Crossq,
}

impl Method {
    /// Table 1's order: the paper's SAC (and its variants) and DDPG, then ours.
    pub const ORDER: [Method; 7] =
        [Method::Sac, Method::Droq, Method::Redq, Method::Ddpg, Method::Td3, Method::Ppo, Method::Crossq];

    /// The method a run's config is: its algorithm, or for SAC, DroQ when its critics have
    /// dropout, else REDQ when its targets use a subset of its critics.
    pub fn of(cfg: &Config) -> Method {
        match cfg.agent.algo {
            Algo::Sac => {
                let sac = cfg.agent.sac();
                if sac.critic_dropout > 0.0 {
                    Method::Droq
                } else if sac.critic_subset.is_some_and(|m| m < sac.n_critics) {
                    Method::Redq
                } else {
                    Method::Sac
                }
            }
            a => Method::from(a),
        }
    }

    /// The algorithm that trains it.
    pub fn algo(self) -> Algo {
        match self {
            Method::Sac | Method::Droq | Method::Redq => Algo::Sac,
            Method::Ddpg => Algo::Ddpg,
            Method::Td3 => Algo::Td3,
            Method::Ppo => Algo::Ppo,
            Method::Crossq => Algo::Crossq,
        }
    }

    /// Its name as the papers print it.
    pub fn title(self) -> &'static str {
        match self {
            Method::Sac => "SAC",
            Method::Droq => "DroQ",
            Method::Redq => "REDQ",
            Method::Ddpg => "DDPG",
            Method::Td3 => "TD3",
            Method::Ppo => "PPO",
            Method::Crossq => "CrossQ",
        }
    }
}

impl From<Algo> for Method {
    fn from(a: Algo) -> Method {
        match a {
            Algo::Sac => Method::Sac,
            Algo::Ddpg => Method::Ddpg,
            Algo::Td3 => Method::Td3,
            Algo::Ppo => Method::Ppo,
            Algo::Crossq => Method::Crossq,
        }
    }
}

impl std::fmt::Display for Method {
    /// Lower case, as an algorithm's name (`sac`, `droq`, ...).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = match self {
            Method::Droq => "droq",
            Method::Redq => "redq",
            m => m.algo().name(),
        };
        f.pad(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sac_variants_are_named_by_their_settings() {
        let mut c = Config::default();
        c.agent.algo = Algo::Sac;
        assert_eq!(Method::of(&c), Method::Sac);
        // Layer norm alone (the obstacle preset's critics) is still SAC.
        c.agent.sac = Some(crate::agent::SacConfig { critic_layer_norm: true, ..Default::default() });
        assert_eq!(Method::of(&c), Method::Sac);
        c.agent.sac = Some(crate::agent::SacConfig {
            critic_dropout: 0.01,
            critic_layer_norm: true,
            ..Default::default()
        });
        assert_eq!(
            (Method::of(&c), Method::of(&c).title(), Method::of(&c).to_string()),
            (Method::Droq, "DroQ", "droq".into())
        );
        c.agent.sac =
            Some(crate::agent::SacConfig { n_critics: 10, critic_subset: Some(2), ..Default::default() });
        assert_eq!(Method::of(&c), Method::Redq);
        // All critics in the target: SAC with a larger ensemble.
        c.agent.sac =
            Some(crate::agent::SacConfig { n_critics: 4, critic_subset: Some(4), ..Default::default() });
        assert_eq!(Method::of(&c), Method::Sac);
        for a in Algo::ALL {
            assert_eq!(Method::from(a).algo(), a);
            assert_eq!(Method::from(a).to_string(), a.name());
        }
        c.agent.algo = Algo::Crossq;
        assert_eq!(Method::of(&c), Method::Crossq);
    }
}
