-- proactive-nav shared-database contract.
--
-- This file is the single source of truth for every contract table. It is a list of numbered
-- migrations; `common.contract.migrate.apply_migrations` applies, in one transaction each,
-- those not yet recorded in schema_version. An applied migration is never edited: change the
-- contract by appending a new one. CONTRACT.md documents every table in language-neutral terms.
--
-- Units: metres, radians, seconds, m/s, rad/s, watt-hours, watts. "stamp" columns are sim time
-- in seconds (the sim's clock), "*_at" timestamptz columns are wall-clock times.

-- migration 1: initial contract
CREATE TABLE robot (
    robot_id            text PRIMARY KEY CHECK (robot_id ~ '^[A-Za-z0-9_-]+$'),
    model               text NOT NULL DEFAULT 'turtlebot3_burger',
    wheel_radius_m      double precision NOT NULL DEFAULT 0.033,
    wheel_separation_m  double precision NOT NULL DEFAULT 0.160,
    max_linear_mps      double precision NOT NULL DEFAULT 0.22,
    max_angular_rps     double precision NOT NULL DEFAULT 2.84,
    footprint_radius_m  double precision NOT NULL DEFAULT 0.105,
    battery_capacity_wh double precision NOT NULL DEFAULT 19.98,
    world               text,
    registered_at       timestamptz NOT NULL DEFAULT now()
);

CREATE TABLE odometry (
    id          bigserial PRIMARY KEY,
    robot_id    text NOT NULL REFERENCES robot ON DELETE CASCADE,
    stamp       double precision NOT NULL,
    seq         bigint NOT NULL DEFAULT 0,
    x           double precision NOT NULL,
    y           double precision NOT NULL,
    yaw         double precision NOT NULL,
    linear_mps  double precision NOT NULL,
    angular_rps double precision NOT NULL,
    received_at timestamptz NOT NULL DEFAULT clock_timestamp()
);
CREATE INDEX odometry_robot_newest ON odometry (robot_id, id DESC);

CREATE TABLE laser_scan (
    id              bigserial PRIMARY KEY,
    robot_id        text NOT NULL REFERENCES robot ON DELETE CASCADE,
    stamp           double precision NOT NULL,
    seq             bigint NOT NULL DEFAULT 0,
    angle_min       double precision NOT NULL,
    angle_increment double precision NOT NULL,
    range_min       double precision NOT NULL,
    range_max       double precision NOT NULL,
    ranges          real[] NOT NULL,
    received_at     timestamptz NOT NULL DEFAULT clock_timestamp()
);
CREATE INDEX laser_scan_robot_newest ON laser_scan (robot_id, id DESC);

CREATE TABLE battery (
    id          bigserial PRIMARY KEY,
    robot_id    text NOT NULL REFERENCES robot ON DELETE CASCADE,
    stamp       double precision NOT NULL,
    energy_wh   double precision NOT NULL CHECK (energy_wh >= 0),
    capacity_wh double precision NOT NULL CHECK (capacity_wh > 0),
    percentage  double precision NOT NULL CHECK (percentage BETWEEN 0 AND 100),
    charging    boolean NOT NULL DEFAULT false,
    power_w     double precision NOT NULL DEFAULT 0,
    received_at timestamptz NOT NULL DEFAULT clock_timestamp()
);
CREATE INDEX battery_robot_newest ON battery (robot_id, id DESC);

CREATE TABLE collision_event (
    id          bigserial PRIMARY KEY,
    robot_id    text NOT NULL REFERENCES robot ON DELETE CASCADE,
    stamp       double precision NOT NULL,
    other       text NOT NULL,
    x           double precision NOT NULL,
    y           double precision NOT NULL,
    received_at timestamptz NOT NULL DEFAULT clock_timestamp()
);
CREATE INDEX collision_event_robot_newest ON collision_event (robot_id, id DESC);

CREATE TABLE map (
    map_id          text PRIMARY KEY,
    resolution_m    double precision NOT NULL CHECK (resolution_m > 0),
    origin_x        double precision NOT NULL,
    origin_y        double precision NOT NULL,
    origin_yaw      double precision NOT NULL DEFAULT 0,
    width           integer NOT NULL CHECK (width > 0),
    height          integer NOT NULL CHECK (height > 0),
    -- row-major, row 0 at origin_y (bottom), one byte per cell: 0 free, 100 occupied, 255 unknown
    grid            bytea NOT NULL CHECK (length(grid) = width * height),
    source          text NOT NULL DEFAULT '',
    loaded_at       timestamptz NOT NULL DEFAULT now()
);

CREATE TABLE charging_station (
    station_id     text PRIMARY KEY,
    map_id         text REFERENCES map ON DELETE CASCADE,
    x              double precision NOT NULL,
    y              double precision NOT NULL,
    radius_m       double precision NOT NULL CHECK (radius_m > 0),
    charge_power_w double precision NOT NULL CHECK (charge_power_w > 0)
);

CREATE TABLE goal (
    id            bigserial PRIMARY KEY,
    robot_id      text NOT NULL REFERENCES robot ON DELETE CASCADE,
    x             double precision NOT NULL,
    y             double precision NOT NULL,
    tolerance_m   double precision NOT NULL DEFAULT 0.15 CHECK (tolerance_m > 0),
    status        text NOT NULL DEFAULT 'active'
                  CHECK (status IN ('active', 'reached', 'cancelled', 'superseded', 'failed')),
    reason        text,
    created_at    timestamptz NOT NULL DEFAULT now(),
    stamp         double precision,
    finished_stamp double precision
);
-- at most one active goal per robot: a new goal supersedes the old one
CREATE UNIQUE INDEX goal_one_active ON goal (robot_id) WHERE status = 'active';

CREATE TABLE strategy (
    code                 text PRIMARY KEY CHECK (code ~ '^[A-Z0-9_]+$'),
    planner_scenario     text,
    controller_scenarios text[] NOT NULL DEFAULT '{}',
    params               jsonb NOT NULL DEFAULT '{}',
    description          text NOT NULL DEFAULT '',
    created_at           timestamptz NOT NULL DEFAULT now()
);

INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) VALUES
    ('GOTO_AVOID', 'turn_then_move', '{avoid_left,avoid_right,safety_stop}',
     '{"target": "goal", "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05}',
     'go to the goal, avoiding obstacles'),
    ('GOTO_DIRECT', 'turn_then_move', '{safety_stop}',
     '{"target": "goal", "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05}',
     'go straight to the goal; no avoidance, but safety_stop still holds'),
    ('CHARGE', 'turn_then_move', '{avoid_left,avoid_right,safety_stop}',
     '{"target": "nearest_charger", "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05,
       "resume_at_pct": 100, "resume_margin": 3.0}',
     'go to the nearest charging station and charge, then resume'),
    ('IDLE', NULL, '{}', '{}', 'stand still');

CREATE TABLE user_command (
    id          bigserial PRIMARY KEY,
    robot_id    text NOT NULL REFERENCES robot ON DELETE CASCADE,
    command     text NOT NULL,
    argument    text,
    status      text NOT NULL DEFAULT 'pending'
                CHECK (status IN ('pending', 'accepted', 'rejected')),
    reason      text,
    created_at  timestamptz NOT NULL DEFAULT now(),
    treated_at  timestamptz
);
CREATE INDEX user_command_pending ON user_command (robot_id, id) WHERE status = 'pending';

CREATE TABLE command_recommendation (
    id              bigserial PRIMARY KEY,
    robot_id        text NOT NULL REFERENCES robot ON DELETE CASCADE,
    kind            text NOT NULL CHECK (kind IN ('robot', 'system')),
    source          text NOT NULL,
    priority        integer NOT NULL,
    linear_mps      double precision,
    angular_rps     double precision,
    system_command  text,
    stamp           double precision NOT NULL,
    expires_stamp   double precision NOT NULL,
    inputs          jsonb NOT NULL DEFAULT '{}',
    reason          text NOT NULL DEFAULT '',
    treated_by      bigint,
    created_at      timestamptz NOT NULL DEFAULT clock_timestamp(),
    CHECK (expires_stamp >= stamp),
    CHECK (kind <> 'robot' OR (linear_mps IS NOT NULL AND angular_rps IS NOT NULL)),
    CHECK (kind <> 'system' OR system_command IS NOT NULL)
);
CREATE INDEX command_recommendation_live ON command_recommendation (robot_id, kind, expires_stamp);

CREATE TABLE command2robot (
    id                bigserial PRIMARY KEY,
    robot_id          text NOT NULL REFERENCES robot ON DELETE CASCADE,
    stamp             double precision NOT NULL,
    linear_mps        double precision NOT NULL,
    angular_rps       double precision NOT NULL,
    recommendation_id bigint,
    source            text,
    considered_ids    bigint[] NOT NULL DEFAULT '{}',
    reason            text NOT NULL DEFAULT '',
    created_at        timestamptz NOT NULL DEFAULT clock_timestamp()
);
CREATE INDEX command2robot_robot_newest ON command2robot (robot_id, id DESC);

CREATE TABLE system_command (
    id                bigserial PRIMARY KEY,
    robot_id          text NOT NULL REFERENCES robot ON DELETE CASCADE,
    command           text NOT NULL,
    recommendation_id bigint,
    considered_ids    bigint[] NOT NULL DEFAULT '{}',
    reason            text NOT NULL DEFAULT '',
    status            text NOT NULL DEFAULT 'pending'
                      CHECK (status IN ('pending', 'accepted', 'rejected')),
    status_reason     text,
    stamp             double precision,
    created_at        timestamptz NOT NULL DEFAULT clock_timestamp(),
    treated_at        timestamptz
);
CREATE INDEX system_command_pending ON system_command (robot_id, id) WHERE status = 'pending';

CREATE TABLE active_strategy (
    robot_id        text PRIMARY KEY REFERENCES robot ON DELETE CASCADE,
    strategy_code   text NOT NULL REFERENCES strategy,
    resume_code     text REFERENCES strategy,
    source          text NOT NULL DEFAULT 'default'
                    CHECK (source IN ('default', 'user', 'system')),
    command_id      bigint,
    stamp           double precision,
    updated_at      timestamptz NOT NULL DEFAULT now()
);

CREATE TABLE engine_stats (
    service        text NOT NULL,
    instance       text NOT NULL,
    rule_type      text NOT NULL,
    scenario       text NOT NULL DEFAULT '',
    executed       bigint NOT NULL DEFAULT 0,
    activated      bigint NOT NULL DEFAULT 0,
    acted          bigint NOT NULL DEFAULT 0,
    errors         bigint NOT NULL DEFAULT 0,
    total_time_s   double precision NOT NULL DEFAULT 0,
    max_time_s     double precision NOT NULL DEFAULT 0,
    updated_at     timestamptz NOT NULL DEFAULT now(),
    PRIMARY KEY (service, instance, rule_type)
);

CREATE TABLE retention_policy (
    table_name          text PRIMARY KEY
                        CHECK (table_name IN ('odometry', 'laser_scan', 'battery', 'collision_event')),
    keep_rows_per_robot integer NOT NULL CHECK (keep_rows_per_robot >= 1)
);
INSERT INTO retention_policy (table_name, keep_rows_per_robot) VALUES
    ('odometry', 900),          -- 30 s at 30 Hz
    ('laser_scan', 150),        -- 30 s at 5 Hz
    ('battery', 300),
    ('collision_event', 1000);

-- Deletes the oldest sensor rows beyond each table's keep_rows_per_robot, per robot.
-- Returns the number of rows deleted. Writers of sensor tables call it now and then.
CREATE FUNCTION prune_sensor_rows() RETURNS bigint LANGUAGE plpgsql AS $$
DECLARE
    pol record;
    rid text;
    cutoff bigint;
    n bigint;
    total bigint := 0;
BEGIN
    FOR pol IN SELECT table_name, keep_rows_per_robot FROM retention_policy LOOP
        FOR rid IN SELECT robot_id FROM robot LOOP
            EXECUTE format(
                'SELECT id FROM %I WHERE robot_id = $1 ORDER BY id DESC OFFSET $2 LIMIT 1',
                pol.table_name)
              INTO cutoff USING rid, pol.keep_rows_per_robot;
            IF cutoff IS NOT NULL THEN
                EXECUTE format('DELETE FROM %I WHERE robot_id = $1 AND id <= $2', pol.table_name)
                  USING rid, cutoff;
                GET DIAGNOSTICS n = ROW_COUNT;
                total := total + n;
            END IF;
        END LOOP;
    END LOOP;
    RETURN total;
END;
$$;

-- migration 2: robot leases of replicated scenario services
--
-- Replicas of one scenario service split the robots between them. Who handles a robot is
-- decided by a Postgres session-level advisory lock, never by this table: a replica owns
-- robot R of service S while its one dedicated lock connection holds the exclusive advisory
-- lock (lease_key(S), lease_key(R)), and counts as a live replica of S while that connection
-- holds the shared lock (lease_key(S), 0). Postgres drops both the moment the connection
-- ends (a crash, a kill, a network loss noticed by idle_session_timeout), so a dead
-- replica's robots are free for the others at once. robot_lease is the history of who held
-- what, for people and tests, written by the holders through the two functions below.

-- A lock key: the first 31 bits of sha256(name), never 0 (0 is the membership key).
CREATE FUNCTION lease_key(name text) RETURNS integer
LANGUAGE sql IMMUTABLE STRICT PARALLEL SAFE AS $$
    SELECT greatest(1, ('x' || substr(encode(sha256(convert_to(name, 'UTF8')), 'hex'), 1, 8))
                       ::bit(32)::integer & 2147483647)
$$;

CREATE TABLE robot_lease (
    id          bigserial PRIMARY KEY,
    service     text NOT NULL,
    robot_id    text NOT NULL REFERENCES robot ON DELETE CASCADE,
    instance    text NOT NULL,
    backend_pid integer NOT NULL,
    acquired_at timestamptz NOT NULL DEFAULT clock_timestamp(),
    released_at timestamptz,
    reason      text,
    CHECK (released_at IS NULL OR released_at >= acquired_at)
);
-- at most one holder at a time per (service, robot): the lock guarantees it, the index
-- keeps the history honest
CREATE UNIQUE INDEX robot_lease_one_holder ON robot_lease (service, robot_id)
    WHERE released_at IS NULL;
CREATE INDEX robot_lease_service_robot ON robot_lease (service, robot_id, id DESC);

-- Try to take robot p_robot for service p_service on this session: returns the new
-- robot_lease id, or NULL if another session holds it. Closes a row left open by a holder
-- that died (reason 'holder gone': its lock went with its connection).
CREATE FUNCTION robot_lease_acquire(p_service text, p_robot text, p_instance text)
RETURNS bigint LANGUAGE plpgsql AS $$
DECLARE
    k1 integer := lease_key(p_service);
    k2 integer := lease_key(p_robot);
    lease bigint;
BEGIN
    IF NOT pg_try_advisory_lock(k1, k2) THEN
        RETURN NULL;
    END IF;
    BEGIN
        UPDATE robot_lease SET released_at = clock_timestamp(), reason = 'holder gone'
         WHERE service = p_service AND robot_id = p_robot AND released_at IS NULL;
        INSERT INTO robot_lease (service, robot_id, instance, backend_pid)
        VALUES (p_service, p_robot, p_instance, pg_backend_pid())
        RETURNING id INTO lease;
    EXCEPTION WHEN OTHERS THEN
        -- a session lock outlives the transaction: give it back before failing
        PERFORM pg_advisory_unlock(k1, k2);
        RAISE;
    END;
    RETURN lease;
END;
$$;

-- Give robot p_robot of service p_service back: the history row is closed first, then the
-- lock is released, so the next holder's acquired_at is never before this released_at.
-- Returns whether this session held the lock.
CREATE FUNCTION robot_lease_release(p_service text, p_robot text, p_reason text)
RETURNS boolean LANGUAGE plpgsql AS $$
BEGIN
    UPDATE robot_lease SET released_at = clock_timestamp(), reason = p_reason
     WHERE service = p_service AND robot_id = p_robot AND released_at IS NULL
       AND backend_pid = pg_backend_pid();
    RETURN pg_advisory_unlock(lease_key(p_service), lease_key(p_robot));
END;
$$;

-- migration 3: refuse non-finite and absurd values
--
-- Postgres accepts NaN, Infinity and -Infinity in double precision columns, and sorts NaN
-- above every number: a CHECK such as `tolerance_m > 0` lets NaN through. From here on every
-- number a person, a recommender or a sensor writes must be finite, and the numbers that
-- steer a robot must also lie within bounds no real ground robot comes near (CONTRACT.md,
-- "Refused values", gives each bound and why). A refused row fails its INSERT or UPDATE with
-- SQLSTATE 23514 (check_violation), naming the constraint.
--
-- Rows already present that break the new rules: the rows that are only the last seconds of
-- sensing and recommending (sensor rows, recommendations) and goals (which could
-- never have been obeyed) are deleted, so their constraints hold for every row. Rows that
-- others refer to or that are state and history (robot, map, charging_station, strategy,
-- active_strategy, system_command: deleting would cascade, break a reference or reset a
-- robot) keep their values; their constraints are added NOT VALID: enforced on every row
-- inserted or updated from now on.

-- true for every number but NaN, Infinity and -Infinity; NULL for NULL, which a CHECK
-- accepts, so a nullable column stays nullable. Not STRICT (NULL gives NULL anyway): a STRICT
-- function around a non-strict AND is never inlined, and sensor rows check it at 30 Hz a robot.
CREATE FUNCTION is_finite(v double precision) RETURNS boolean
LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT v > '-Infinity'::double precision AND v < 'Infinity'::double precision
$$;

-- strategy.params: a JSON object whose top-level numbers are within +-1e6 (JSON itself has no
-- NaN or Infinity, but 1e400 is valid JSON and reads back as Infinity in most languages)
CREATE FUNCTION strategy_params_sane(p jsonb) RETURNS boolean
LANGUAGE sql IMMUTABLE STRICT PARALLEL SAFE AS $$
    SELECT jsonb_typeof(p) = 'object' AND NOT EXISTS (
        SELECT 1 FROM jsonb_each(p) AS e
         WHERE jsonb_typeof(e.value) = 'number' AND abs(e.value::numeric) > 1e6)
$$;

-- people: goal
DELETE FROM goal
 WHERE NOT (abs(x) <= 1e5 AND abs(y) <= 1e5 AND tolerance_m > 0 AND tolerance_m <= 100
            AND coalesce(is_finite(stamp), true) AND coalesce(is_finite(finished_stamp), true));
ALTER TABLE goal
    ADD CONSTRAINT goal_xy_bounded CHECK (abs(x) <= 1e5 AND abs(y) <= 1e5),
    ADD CONSTRAINT goal_tolerance_bounded CHECK (tolerance_m > 0 AND tolerance_m <= 100),
    ADD CONSTRAINT goal_stamps_finite CHECK (is_finite(stamp) AND is_finite(finished_stamp));

-- people and migrations: strategy (referenced by active_strategy: NOT VALID, see above)
ALTER TABLE strategy
    ADD CONSTRAINT strategy_params_sane CHECK (strategy_params_sane(params)) NOT VALID;

-- recommenders: command_recommendation
DELETE FROM command_recommendation
 WHERE NOT (priority BETWEEN 0 AND 1000
            AND (priority < 100 OR (kind = 'robot' AND linear_mps = 0))
            AND coalesce(abs(linear_mps) <= 10, true) AND coalesce(abs(angular_rps) <= 20, true)
            AND is_finite(stamp) AND is_finite(expires_stamp));
ALTER TABLE command_recommendation
    ADD CONSTRAINT command_recommendation_priority_bounded CHECK (priority BETWEEN 0 AND 1000),
    -- the safety band: a recommendation at priority 100 or above may only stop the robot's
    -- travel (turning in place is allowed), so nothing that outranks safety_stop can drive
    ADD CONSTRAINT command_recommendation_safety_band
        CHECK (priority < 100 OR (kind = 'robot' AND linear_mps = 0)),
    ADD CONSTRAINT command_recommendation_velocity_bounded
        CHECK (abs(linear_mps) <= 10 AND abs(angular_rps) <= 20),
    ADD CONSTRAINT command_recommendation_stamps_finite
        CHECK (is_finite(stamp) AND is_finite(expires_stamp));

-- the decision service. command2robot gets no constraint: its values are copied from the
-- recommendations above, and its reader (the bridge) clamps to the robot's limits and turns
-- NaN into 0 for any writer (docs/BRIDGE.md), a guard that stays testable through the table.
ALTER TABLE system_command
    ADD CONSTRAINT system_command_stamp_finite CHECK (is_finite(stamp)) NOT VALID;
ALTER TABLE active_strategy
    ADD CONSTRAINT active_strategy_stamp_finite CHECK (is_finite(stamp)) NOT VALID;

-- the bridge: sensor rows (it already refuses non-finite messages; the database now says so
-- to every other writer too). laser_scan.ranges keeps Infinity: "nothing within range_max".
DELETE FROM odometry
 WHERE NOT (is_finite(stamp) AND is_finite(x) AND is_finite(y) AND is_finite(yaw)
            AND is_finite(linear_mps) AND is_finite(angular_rps));
ALTER TABLE odometry
    ADD CONSTRAINT odometry_finite CHECK (is_finite(stamp) AND is_finite(x) AND is_finite(y)
        AND is_finite(yaw) AND is_finite(linear_mps) AND is_finite(angular_rps));
DELETE FROM laser_scan
 WHERE NOT (is_finite(stamp) AND is_finite(angle_min) AND is_finite(angle_increment)
            AND is_finite(range_min) AND is_finite(range_max));
ALTER TABLE laser_scan
    ADD CONSTRAINT laser_scan_finite CHECK (is_finite(stamp) AND is_finite(angle_min)
        AND is_finite(angle_increment) AND is_finite(range_min) AND is_finite(range_max));
DELETE FROM battery
 WHERE NOT (is_finite(stamp) AND is_finite(energy_wh) AND is_finite(capacity_wh)
            AND is_finite(power_w));
ALTER TABLE battery
    ADD CONSTRAINT battery_finite CHECK (is_finite(stamp) AND is_finite(energy_wh)
        AND is_finite(capacity_wh) AND is_finite(power_w));
DELETE FROM collision_event WHERE NOT (is_finite(stamp) AND is_finite(x) AND is_finite(y));
ALTER TABLE collision_event
    ADD CONSTRAINT collision_event_finite CHECK (is_finite(stamp) AND is_finite(x) AND is_finite(y));

-- the bridge: the world (referenced by other rows: NOT VALID, see above)
ALTER TABLE robot
    ADD CONSTRAINT robot_limits_finite CHECK (is_finite(wheel_radius_m)
        AND is_finite(wheel_separation_m) AND is_finite(max_linear_mps)
        AND is_finite(max_angular_rps) AND is_finite(footprint_radius_m)
        AND is_finite(battery_capacity_wh)) NOT VALID;
ALTER TABLE map
    ADD CONSTRAINT map_finite CHECK (is_finite(resolution_m) AND is_finite(origin_x)
        AND is_finite(origin_y) AND is_finite(origin_yaw)) NOT VALID;
ALTER TABLE charging_station
    ADD CONSTRAINT charging_station_finite CHECK (is_finite(x) AND is_finite(y)
        AND is_finite(radius_m) AND is_finite(charge_power_w)) NOT VALID;

-- migration 4: the bridge's safety layer writes what it did with a command
--
-- The bridge checks every command2robot row against the robot's newest laser scan before it
-- becomes a cmd_vel, whatever priority chose it (docs/BRIDGE.md, "Safety layer"). When the
-- layer limited or stopped the command, or had no fresh scan to check it against, it says so
-- here with one UPDATE after the cmd_vel went out. These three columns are the only ones of
-- command2robot the bridge writes; NULL: sent as decided (clamped to the robot's limits).
ALTER TABLE command2robot
    ADD COLUMN safety text,
    ADD COLUMN sent_linear_mps double precision,
    ADD COLUMN sent_angular_rps double precision;

-- migration 5: the robot row describes the whole robot model
--
-- Until now every robot was a TurtleBot3 Burger and the scenarios knew its acceleration and
-- its lidar as constants. A robot model (models/*.yaml, docs/SIM.md) now names them, the
-- bridge writes them here from the sim's world message, and every scenario reads the
-- robot's footprint, limits and sensor from this row. The defaults are the Burger's (its
-- LDS-01 lidar; models/turtlebot3_burger.yaml gives the sources of the acceleration limits),
-- so rows written before this migration, and writers that do not know the columns, describe
-- the Burger.
ALTER TABLE robot
    ADD COLUMN max_linear_accel_mps2  double precision NOT NULL DEFAULT 2.5,
    ADD COLUMN max_angular_accel_rps2 double precision NOT NULL DEFAULT 31.25,
    ADD COLUMN lidar_beams            integer NOT NULL DEFAULT 360,
    ADD COLUMN lidar_angle_min_rad    double precision NOT NULL DEFAULT 0.0,
    ADD COLUMN lidar_fov_rad          double precision NOT NULL DEFAULT 6.283185307179586,
    ADD COLUMN lidar_range_min_m      double precision NOT NULL DEFAULT 0.12,
    ADD COLUMN lidar_range_max_m      double precision NOT NULL DEFAULT 3.5,
    ADD COLUMN lidar_noise_m          double precision NOT NULL DEFAULT 0.01,
    ADD COLUMN lidar_rate_hz          double precision NOT NULL DEFAULT 5.0,
    ADD CONSTRAINT robot_accel_bounded CHECK (
        max_linear_accel_mps2 > 0 AND max_linear_accel_mps2 <= 100
        AND max_angular_accel_rps2 > 0 AND max_angular_accel_rps2 <= 100),
    ADD CONSTRAINT robot_lidar_sane CHECK (
        lidar_beams BETWEEN 1 AND 100000
        AND abs(lidar_angle_min_rad) <= 6.283185307179586
        AND lidar_fov_rad > 0 AND lidar_fov_rad <= 6.283185307179586
        AND lidar_range_min_m >= 0 AND lidar_range_max_m > lidar_range_min_m
        AND lidar_range_max_m <= 1000
        AND lidar_noise_m >= 0 AND lidar_noise_m <= 10
        AND lidar_rate_hz > 0 AND lidar_rate_hz <= 1000);

-- migration 6: the planner publishes the path it follows
--
-- The path was the planner's private state. People (the dashboard, recordings) want to see
-- it and local controllers that score trajectories against it need it, so the planner now
-- writes one row each time it plans or re-plans a robot's route, and the newest row per robot
-- is the path in force (an empty path: the planner has none, e.g. the target was reached or
-- is unreachable). Bounded like the sensor tables.
CREATE TABLE planned_path (
    id          bigserial PRIMARY KEY,
    robot_id    text NOT NULL REFERENCES robot ON DELETE CASCADE,
    stamp       double precision NOT NULL CHECK (is_finite(stamp)),
    goal_id     bigint REFERENCES goal ON DELETE SET NULL,
    target      text NOT NULL CHECK (target IN ('goal', 'charger', 'none')),
    target_x    double precision CHECK (abs(target_x) <= 1e5),
    target_y    double precision CHECK (abs(target_y) <= 1e5),
    xs          double precision[] NOT NULL,
    ys          double precision[] NOT NULL,
    length_m    double precision NOT NULL CHECK (length_m >= 0 AND is_finite(length_m)),
    created_at  timestamptz NOT NULL DEFAULT now(),
    CONSTRAINT planned_path_points CHECK (
        cardinality(xs) = cardinality(ys) AND cardinality(xs) <= 100000)
);
CREATE INDEX planned_path_newest ON planned_path (robot_id, id DESC);

ALTER TABLE retention_policy DROP CONSTRAINT retention_policy_table_name_check;
ALTER TABLE retention_policy ADD CONSTRAINT retention_policy_table_name_check
    CHECK (table_name IN ('odometry', 'laser_scan', 'battery', 'collision_event', 'planned_path'));
INSERT INTO retention_policy (table_name, keep_rows_per_robot) VALUES ('planned_path', 200);

-- migration 7: a collision event is one row, however often the robot sends it
--
-- The sim sent a collision event once; a router stall or a Postgres outage lost it, though
-- the contract says collision events are never dropped. The robot now resends each event
-- until the bridge acknowledges its committed row (CONTRACT.md, "Robot and sim"), so the
-- bridge may receive one event several times: one row per (robot, run, seq), where `run`
-- names the robot driver's run (new at every start, since `seq` starts again from 0 then).
-- Rows written before, and writers that send no `run`, hold NULLs, which the index never
-- compares: they are inserted as before.
ALTER TABLE collision_event
    ADD COLUMN seq bigint CHECK (seq >= 0),
    ADD COLUMN run text CHECK (length(run) BETWEEN 1 AND 64);
CREATE UNIQUE INDEX collision_event_once ON collision_event (robot_id, run, seq);

-- migration 8: GOTO_FAST, the robot's own speed with a local controller and recovery
--
-- The planner plans and publishes the path (planned_path), decides arrival and failure, and
-- does not drive ("planner_drives": false); the dwa local controller drives along the path at
-- the robot's limits (docs/CONTROLLER.md); the planner's recovery rule backs up, rotates and
-- re-plans when the robot is stuck, then gives the goal up with a reason
-- (docs/PLANNER.md, "Recovery"); safety_stop keeps the last word.
INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) VALUES
    ('GOTO_FAST', 'turn_then_move', '{dwa,safety_stop}',
     '{"target": "goal", "planner_drives": false, "recovery": true, "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05}',
     'go to the goal at the robot''s speed: dwa along the planned path, recovery when stuck, safety_stop');

-- migration 9: least privilege: pruning as its owner, each family's own lease and stats rows
--
-- Every service now connects as its own role, which may write only the tables CONTRACT.md's
-- "Roles" table grants it (common/contract/roles.py creates the roles and applies the
-- GRANTs; roles are cluster-wide and passwords per deployment, so neither is a migration).
-- prune_sensor_rows() deletes old rows of every table of retention_policy, planned_path
-- among them, which its caller (the bridge) does not write: it now runs as its owner
-- (SECURITY DEFINER), with a search_path no caller can redirect to tables of its own, and
-- only the roles granted EXECUTE may call it.
ALTER FUNCTION prune_sensor_rows() SECURITY DEFINER SET search_path = public, pg_temp;
REVOKE EXECUTE ON FUNCTION prune_sensor_rows() FROM PUBLIC;

-- Two tables are written by every scenario service, each under its own name in `service`:
-- robot_lease and engine_stats. A GRANT cannot say "only your own rows", so row security
-- does: a role of the pnav_<family> naming (common/contract/roles.py) may insert and change
-- only rows whose `service` is its family (a planner cannot take or close a controller's
-- lease, nor write its statistics); every role reads every row. The tables' owner and
-- superusers are not subject to row security; a role outside the naming (a deployment's own
-- account) is not restricted either.
CREATE FUNCTION writes_as(p_service text) RETURNS boolean
LANGUAGE sql STABLE PARALLEL SAFE AS $$
    SELECT current_user NOT LIKE 'pnav\_%' OR current_user = 'pnav_' || p_service
$$;
ALTER TABLE robot_lease ENABLE ROW LEVEL SECURITY;
CREATE POLICY robot_lease_read ON robot_lease FOR SELECT USING (true);
CREATE POLICY robot_lease_insert ON robot_lease FOR INSERT WITH CHECK (writes_as(service));
CREATE POLICY robot_lease_update ON robot_lease FOR UPDATE
    USING (writes_as(service)) WITH CHECK (writes_as(service));
ALTER TABLE engine_stats ENABLE ROW LEVEL SECURITY;
CREATE POLICY engine_stats_read ON engine_stats FOR SELECT USING (true);
CREATE POLICY engine_stats_insert ON engine_stats FOR INSERT WITH CHECK (writes_as(service));
CREATE POLICY engine_stats_update ON engine_stats FOR UPDATE
    USING (writes_as(service)) WITH CHECK (writes_as(service));

-- migration 10: robot leases only the service roles can take or block
--
-- Any role could take an advisory lock of any key, and the lease keys are public
-- (lease_key is sha256 of the names): a people's session holding (lease_key(S), 0) shared
-- counted as a replica of S, so the real one gave half its robots back to it, and one
-- holding (lease_key(S), lease_key(R)) kept robot R from every replica. Two defences:
--
-- 1. Taking an advisory lock is a privilege. common/contract/roles.py (run by the
--    superuser who sets the database up) revokes EXECUTE on every pg_catalog function
--    that takes one (pg_advisory_lock, _shared, _xact, pg_try_*...) from PUBLIC in this
--    database and grants it to the roles that may hold leases (those CONTRACT.md's Roles
--    table lets INSERT into robot_lease) and to pnav_owner (the migrations' lock). A
--    catalog privilege is not a migration (it needs a superuser), hence there.
-- 2. A lock counts only if its holder may hold leases of S: robot_lease_holders(S), the
--    one read of pg_locks a replica makes per cycle, ignores locks of sessions whose role
--    could not have written S's history (lease_holder_may: INSERT on robot_lease and,
--    for a role of the pnav_<family> naming, the family S, as row security has it). Such
--    a lock is neither a replica nor an owner: nobody gives a robot back for it.
CREATE FUNCTION lease_holder_may(p_service text, p_role oid) RETURNS boolean
LANGUAGE sql STABLE PARALLEL SAFE AS $$
    SELECT coalesce((SELECT (r.rolname::text NOT LIKE 'pnav\_%'
                             OR r.rolname::text = 'pnav_' || p_service)
                            AND has_table_privilege(r.oid, 'robot_lease', 'INSERT')
                       FROM pg_roles r WHERE r.oid = p_role), false)
$$;

-- Every robot with the backend that holds its lease of p_service (NULL: free, or held by a
-- session that may not hold it), then one row (robot_id NULL) per live replica of
-- p_service. pg_locks is read once (the CTE is materialised), so the rows agree; a holder's
-- role is looked up once per backend, not per lock. PL/pgSQL keeps the plan for the session
-- (a replica calls it every cycle on its lock connection).
CREATE FUNCTION robot_lease_holders(p_service text)
RETURNS TABLE (robot_id text, pid integer)
LANGUAGE plpgsql STABLE AS $$
BEGIN
    RETURN QUERY
    WITH locks AS MATERIALIZED (
        SELECT l.objid::bigint AS k, l.pid AS holder, l.mode
          FROM pg_locks l
         WHERE l.locktype = 'advisory' AND l.granted AND l.objsubid = 2
           AND l.database = (SELECT d.oid FROM pg_database d
                              WHERE d.datname = current_database())
           AND l.classid = lease_key(p_service)::oid
    ), allowed AS MATERIALIZED (
        SELECT b.holder
          FROM (SELECT DISTINCT locks.holder FROM locks) b
         CROSS JOIN LATERAL pg_stat_get_activity(b.holder) a
         WHERE lease_holder_may(p_service, a.usesysid)
    ), held AS MATERIALIZED (
        SELECT locks.* FROM locks WHERE locks.holder IN (SELECT allowed.holder FROM allowed)
    )
    SELECT r.robot_id, h.holder
      FROM robot r
      LEFT JOIN held h ON h.k = lease_key(r.robot_id) AND h.mode = 'ExclusiveLock'
    UNION ALL
    SELECT NULL, h.holder FROM held h WHERE h.k = 0 AND h.mode = 'ShareLock';
END;
$$;

-- migration 11: a strategy row is bounded: params depth, size and numbers, short names
--
-- A strategy's params nested 500 deep made every reader that walks them recursively fail
-- (the dashboard stopped listing strategies, pushing and starting); a JSON reader in most
-- languages gives up a few thousand levels down, and a number of 5 000 digits is refused by
-- some (Python's int) and silently rounded by others. From here on params must be a JSON
-- object (migration 3) that is at most 16 deep (the object itself counting one), at most
-- 16 384 bytes as text, and whose every number, however deep, lies within a 64-bit integer's
-- range (+-9223372036854775807); the top-level bound of migration 3 stays. The code is at
-- most 64 characters and the description at most 1 000. common.contract.limits mirrors every
-- bound for tools that refuse first. Rows already present keep their values (the strategy is
-- referenced by active_strategy, see migration 3): the constraints are added NOT VALID, and
-- readers treat params beyond the bounds as unreadable (CONTRACT.md, "Refused values").

-- how deeply objects and arrays nest in p: 0 for a scalar, 1 for {} or {"k": 1}, 2 for
-- {"k": []}... Counted level by level (a recursive CTE, no recursion on the server's stack);
-- with stop_at, no deeper than stop_at + 1, so "deeper than N" costs N levels, not the value's.
CREATE FUNCTION jsonb_depth(p jsonb, stop_at integer DEFAULT NULL) RETURNS integer
LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    WITH RECURSIVE item(v, level) AS (
        SELECT p, 0
        UNION ALL
        SELECT c.v, i.level + 1
          FROM item i CROSS JOIN LATERAL (
              SELECT e.value FROM jsonb_each(
                  CASE jsonb_typeof(i.v) WHEN 'object' THEN i.v ELSE '{}' END) AS e
              UNION ALL
              SELECT a.value FROM jsonb_array_elements(
                  CASE jsonb_typeof(i.v) WHEN 'array' THEN i.v ELSE '[]' END) AS a
          ) AS c(v)
         WHERE stop_at IS NULL OR i.level < stop_at
    )
    SELECT coalesce(max(level + 1) FILTER (WHERE jsonb_typeof(v) IN ('object', 'array')), 0)
      FROM item
$$;

-- true when strategy params are within this migration's bounds (size first: the depth and the
-- numbers are looked at only in a value small enough to look at). Top-level numbers are
-- strategy_params_sane's (a tighter bound), so a refused one is named by that constraint.
CREATE FUNCTION strategy_params_bounded(p jsonb) RETURNS boolean
LANGUAGE sql IMMUTABLE STRICT PARALLEL SAFE AS $$
    SELECT CASE
        WHEN octet_length(p::text) > 16384 THEN false
        WHEN jsonb_depth(p, 16) > 16 THEN false
        ELSE NOT jsonb_path_exists(p, 'strict $.**{2 to last} ? (@.type() == "number" &&
            (@ > 9223372036854775807 || @ < -9223372036854775807))')
    END
$$;

ALTER TABLE strategy
    ADD CONSTRAINT strategy_params_bounded CHECK (strategy_params_bounded(params)) NOT VALID,
    ADD CONSTRAINT strategy_text_bounded
        CHECK (char_length(code) <= 64 AND char_length(description) <= 1000) NOT VALID;

-- migration 12: planners and controllers offer the scenarios they can run
--
-- A strategy names its scenarios by name (planner_scenario, controller_scenarios), and only a
-- planner or controller process knows which it can run: the entry points installed where it
-- runs. A strategy naming one that none can run stopped the robot with its goal `active` and
-- no reason. Each live planner and controller instance now lists what it can run here, one
-- row per scenario, at its start; it refreshes `updated_at` every few seconds and deletes its
-- rows at a clean stop. A reader counts an offer only while it is fresh (CONTRACT.md,
-- scenario_offer): the rows of an instance that died are stale within seconds, and the next
-- instance of its family to publish deletes them. Each family writes only its own rows.
CREATE TABLE scenario_offer (
    service    text NOT NULL CHECK (service IN ('planner', 'controller')),
    instance   text NOT NULL CHECK (length(instance) BETWEEN 1 AND 200),
    scenario   text NOT NULL CHECK (length(scenario) BETWEEN 1 AND 200),
    updated_at timestamptz NOT NULL DEFAULT now(),
    PRIMARY KEY (service, instance, scenario)
);
ALTER TABLE scenario_offer ENABLE ROW LEVEL SECURITY;
CREATE POLICY scenario_offer_read ON scenario_offer FOR SELECT USING (true);
CREATE POLICY scenario_offer_insert ON scenario_offer FOR INSERT WITH CHECK (writes_as(service));
CREATE POLICY scenario_offer_update ON scenario_offer FOR UPDATE
    USING (writes_as(service)) WITH CHECK (writes_as(service));
CREATE POLICY scenario_offer_delete ON scenario_offer FOR DELETE USING (writes_as(service));

-- migration 13: goal poses with a heading, and routes through waypoints
--
-- A goal was a point: a robot could not be told to stop facing a shelf, a dock or a door,
-- nor to drive through a list of places. A goal may now carry a heading: `yaw` (radians, in
-- the map frame, in [-pi, pi]) and `yaw_tolerance_rad` (in (0, pi]; NULL with a yaw: 0.1 rad,
-- the readers' default; a tolerance without a yaw is refused, it would mean nothing). The
-- planner turns the robot in place to it once there, and sets the goal `reached` only when
-- both the position and the heading hold. Rows already present have no yaw: every constraint
-- holds for them, so the constraints are validated.
ALTER TABLE goal
    ADD COLUMN yaw double precision,
    ADD COLUMN yaw_tolerance_rad double precision,
    ADD CONSTRAINT goal_yaw_bounded
        CHECK (is_finite(yaw) AND yaw BETWEEN -pi() AND pi()),
    ADD CONSTRAINT goal_yaw_tolerance_bounded
        CHECK (is_finite(yaw_tolerance_rad) AND yaw_tolerance_rad > 0
               AND yaw_tolerance_rad <= pi()),
    ADD CONSTRAINT goal_yaw_tolerance_needs_yaw
        CHECK (yaw_tolerance_rad IS NULL OR yaw IS NOT NULL);

-- A route: the poses a goal is driven through, in `seq` order, before the goal's own pose
-- (the last one). People insert them with their goal, in its transaction; the planner writes
-- each one's progress (`status`, `reason`, `reached_stamp`). A goal holds at most 1 000 of
-- them: `seq` runs from 1 to 1 000 and is unique per goal, so the cap is the table's own
-- (a list of 10 000 poses fails at the 1 001st, naming goal_waypoint_seq_bounded).
CREATE TABLE goal_waypoint (
    goal_id           bigint NOT NULL REFERENCES goal ON DELETE CASCADE,
    seq               integer NOT NULL,
    x                 double precision NOT NULL,
    y                 double precision NOT NULL,
    tolerance_m       double precision NOT NULL DEFAULT 0.3,
    yaw               double precision,
    yaw_tolerance_rad double precision,
    stop              boolean NOT NULL DEFAULT false,
    status            text NOT NULL DEFAULT 'pending',
    reason            text,
    reached_stamp     double precision,
    created_at        timestamptz NOT NULL DEFAULT now(),
    PRIMARY KEY (goal_id, seq),
    CONSTRAINT goal_waypoint_seq_bounded CHECK (seq BETWEEN 1 AND 1000),
    CONSTRAINT goal_waypoint_xy_bounded
        CHECK (is_finite(x) AND is_finite(y) AND abs(x) <= 1e5 AND abs(y) <= 1e5),
    CONSTRAINT goal_waypoint_tolerance_bounded
        CHECK (is_finite(tolerance_m) AND tolerance_m > 0 AND tolerance_m <= 100),
    CONSTRAINT goal_waypoint_yaw_bounded
        CHECK (is_finite(yaw) AND yaw BETWEEN -pi() AND pi()),
    CONSTRAINT goal_waypoint_yaw_tolerance_bounded
        CHECK (is_finite(yaw_tolerance_rad) AND yaw_tolerance_rad > 0
               AND yaw_tolerance_rad <= pi()),
    CONSTRAINT goal_waypoint_yaw_tolerance_needs_yaw
        CHECK (yaw_tolerance_rad IS NULL OR yaw IS NOT NULL),
    CONSTRAINT goal_waypoint_status_known
        CHECK (status IN ('pending', 'reached', 'failed')),
    CONSTRAINT goal_waypoint_progress_finite
        CHECK (is_finite(reached_stamp) AND char_length(reason) <= 1000)
);

-- migration 14: keepout and speed zones people draw on the map
--
-- Every warehouse has places a robot must not enter and places it must slow down in. A zone
-- is a polygon in the map frame (its vertices' x and y in two arrays, in order, closed
-- implicitly: the last vertex joins the first), of kind `keepout` (the planner never routes
-- through it) or `speed_limit` (the bridge's safety layer caps the linear speed sent to a
-- robot whose centre is inside it at `max_speed_mps`). `robot_id` NULL: every robot; else
-- that robot only. People write the rows (the CLI, dashboards); a change applies at once:
-- the writer notifies `pnav/db/zone/_`, and readers read the table again at least every few
-- tenths of a second anyway (CONTRACT.md, zone).
--
-- A polygon is refused unless it has 3 to 100 vertices, the same number of x and y, every
-- coordinate finite and within +-100 000 m, no vertex repeated by the next (nor the first
-- repeated at the end: it is closed implicitly), not every vertex on one line, no edge
-- crossing, touching or folding back onto another (a simple polygon), and an area of at
-- least 0.01 m^2. zone_polygon_problem
-- says what is wrong in words naming the field; zone_polygon_ok raises it as a
-- check_violation of constraint `zone_polygon`, so every client sees the reason.
-- common.contract.zones mirrors every bound for tools that refuse first.

-- what is wrong with the polygon (xs, ys), or NULL when it is a simple polygon within bounds
CREATE FUNCTION zone_polygon_problem(xs double precision[], ys double precision[])
RETURNS text LANGUAGE plpgsql IMMUTABLE PARALLEL SAFE AS $$
DECLARE
    n integer;
    i integer;
    j integer;
    area double precision := 0;
    collinear boolean;
    x1 double precision; y1 double precision; x2 double precision; y2 double precision;
    x3 double precision; y3 double precision; x4 double precision; y4 double precision;
    d1 double precision; d2 double precision; d3 double precision; d4 double precision;
BEGIN
    IF xs IS NULL OR ys IS NULL THEN
        RETURN 'polygon xs and ys are required';
    END IF;
    IF array_ndims(xs) IS DISTINCT FROM 1 OR array_ndims(ys) IS DISTINCT FROM 1
       OR array_lower(xs, 1) <> 1 OR array_lower(ys, 1) <> 1 THEN
        RETURN 'polygon xs and ys must be one-dimensional arrays of at least 3 vertices';
    END IF;
    n := cardinality(xs);
    IF n <> cardinality(ys) THEN
        RETURN format('polygon xs has %s values but ys has %s: one x and one y per vertex',
                      n, cardinality(ys));
    END IF;
    IF n < 3 THEN
        RETURN format('polygon has %s vertices: at least 3 are needed (fewer make an open '
                      'line, not an area)', n);
    END IF;
    IF n > 100 THEN
        RETURN format('polygon has %s vertices: at most 100', n);
    END IF;
    FOR i IN 1..n LOOP
        IF xs[i] IS NULL OR ys[i] IS NULL OR xs[i] = 'NaN' OR ys[i] = 'NaN'
           OR abs(xs[i]) > 1e5 OR abs(ys[i]) > 1e5 THEN
            RETURN format('polygon vertex %s (xs[%s], ys[%s]) must be finite and within '
                          '+-100000 m, got (%s, %s)', i, i, i, xs[i], ys[i]);
        END IF;
    END LOOP;
    FOR i IN 1..n LOOP
        j := i % n + 1;
        IF xs[i] = xs[j] AND ys[i] = ys[j] THEN
            IF j = 1 THEN
                RETURN format('polygon repeats vertex 1 at the end (vertex %s): a zone is '
                              'closed implicitly, give each vertex once', n);
            END IF;
            RETURN format('polygon vertices %s and %s are the same point: a degenerate edge',
                          i, j);
        END IF;
        area := area + xs[i] * ys[j] - xs[j] * ys[i];
    END LOOP;
    -- every vertex on the line through the first two: no area at all
    collinear := true;
    FOR i IN 3..n LOOP
        IF (xs[2] - xs[1]) * (ys[i] - ys[1]) - (ys[2] - ys[1]) * (xs[i] - xs[1]) <> 0 THEN
            collinear := false;
        END IF;
    END LOOP;
    IF collinear THEN
        RETURN 'polygon is degenerate: its vertices are on one line';
    END IF;
    -- a simple polygon: no two edges meet except adjacent ones at their shared vertex
    FOR i IN 1..n LOOP
        x1 := xs[i]; y1 := ys[i]; x2 := xs[i % n + 1]; y2 := ys[i % n + 1];
        FOR j IN i + 1..n LOOP
            x3 := xs[j]; y3 := ys[j]; x4 := xs[j % n + 1]; y4 := ys[j % n + 1];
            IF j = i + 1 OR (i = 1 AND j = n) THEN
                -- adjacent: they share one vertex; they overlap only when collinear and the
                -- second turns straight back along the first
                IF j = i + 1 THEN
                    d1 := (x2 - x1) * (y4 - y3) - (y2 - y1) * (x4 - x3);
                    d2 := (x2 - x1) * (x4 - x3) + (y2 - y1) * (y4 - y3);
                ELSE
                    d1 := (x1 - x3) * (y2 - y1) - (y1 - y3) * (x2 - x1);
                    d2 := (x1 - x3) * (x2 - x1) + (y1 - y3) * (y2 - y1);
                END IF;
                IF d1 = 0 AND d2 < 0 THEN
                    RETURN format('polygon edges %s and %s fold back onto each other: a '
                                  'zone must not intersect itself', i, j);
                END IF;
                CONTINUE;
            END IF;
            d1 := (x4 - x3) * (y1 - y3) - (y4 - y3) * (x1 - x3);
            d2 := (x4 - x3) * (y2 - y3) - (y4 - y3) * (x2 - x3);
            d3 := (x2 - x1) * (y3 - y1) - (y2 - y1) * (x3 - x1);
            d4 := (x2 - x1) * (y4 - y1) - (y2 - y1) * (x4 - x1);
            IF ((d1 > 0 AND d2 < 0) OR (d1 < 0 AND d2 > 0))
               AND ((d3 > 0 AND d4 < 0) OR (d3 < 0 AND d4 > 0)) THEN
                RETURN format('polygon edges %s and %s cross: a zone must not intersect '
                              'itself (give the vertices in order around it)', i, j);
            END IF;
            IF (d1 = 0 AND least(x3, x4) <= x1 AND x1 <= greatest(x3, x4)
                       AND least(y3, y4) <= y1 AND y1 <= greatest(y3, y4))
               OR (d2 = 0 AND least(x3, x4) <= x2 AND x2 <= greatest(x3, x4)
                          AND least(y3, y4) <= y2 AND y2 <= greatest(y3, y4))
               OR (d3 = 0 AND least(x1, x2) <= x3 AND x3 <= greatest(x1, x2)
                          AND least(y1, y2) <= y3 AND y3 <= greatest(y1, y2))
               OR (d4 = 0 AND least(x1, x2) <= x4 AND x4 <= greatest(x1, x2)
                          AND least(y1, y2) <= y4 AND y4 <= greatest(y1, y2)) THEN
                RETURN format('polygon edges %s and %s touch: a zone must not intersect '
                              'itself', i, j);
            END IF;
        END LOOP;
    END LOOP;
    IF abs(area) / 2 < 0.01 THEN
        RETURN format('polygon is degenerate: its area is %s m^2, at least 0.01 is needed',
                      round((abs(area) / 2)::numeric, 6));
    END IF;
    RETURN NULL;
END;
$$;

-- true for a valid polygon; otherwise raises the problem as constraint zone_polygon's
CREATE FUNCTION zone_polygon_ok(xs double precision[], ys double precision[])
RETURNS boolean LANGUAGE plpgsql IMMUTABLE PARALLEL SAFE AS $$
DECLARE
    problem text := zone_polygon_problem(xs, ys);
BEGIN
    IF problem IS NOT NULL THEN
        RAISE EXCEPTION 'zone %', problem
            USING ERRCODE = 'check_violation', CONSTRAINT = 'zone_polygon', TABLE = 'zone',
                  COLUMN = 'xs, ys';
    END IF;
    RETURN true;
END;
$$;

CREATE TABLE zone (
    name          text PRIMARY KEY CONSTRAINT zone_name_check
                  CHECK (name ~ '^[A-Za-z0-9_.-]{1,64}$'),
    kind          text NOT NULL CONSTRAINT zone_kind_check
                  CHECK (kind IN ('keepout', 'speed_limit')),
    xs            double precision[] NOT NULL,
    ys            double precision[] NOT NULL,
    max_speed_mps double precision CONSTRAINT zone_max_speed_mps_check
                  CHECK (max_speed_mps > 0 AND max_speed_mps <= 10),
    robot_id      text CONSTRAINT zone_robot_id_check CHECK (robot_id ~ '^[A-Za-z0-9_-]+$'),
    description   text NOT NULL DEFAULT '' CONSTRAINT zone_description_check
                  CHECK (char_length(description) <= 1000),
    created_at    timestamptz NOT NULL DEFAULT now(),
    CONSTRAINT zone_polygon CHECK (zone_polygon_ok(xs, ys)),
    CONSTRAINT zone_max_speed_mps_kind CHECK ((kind = 'speed_limit') = (max_speed_mps IS NOT NULL))
);

-- At most 256 zones: every reader tests every zone (the bridge one robot's pose per command,
-- the planner each zone's cells per change), so no number of rows people write may make
-- that work unbounded. A trigger, as a CHECK sees one row: refused as a check_violation of
-- `zone_count`. Two people inserting at the same moment may pass it together by one or two.
CREATE FUNCTION zone_count_bounded() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    IF (SELECT count(*) FROM zone) >= 256 THEN
        RAISE EXCEPTION 'zone table holds at most 256 zones: remove one first'
            USING ERRCODE = 'check_violation', CONSTRAINT = 'zone_count', TABLE = 'zone';
    END IF;
    RETURN NEW;
END;
$$;
CREATE TRIGGER zone_count_bounded BEFORE INSERT ON zone
    FOR EACH ROW EXECUTE FUNCTION zone_count_bounded();

-- migration 15: GOTO_DODGE, GOTO_FAST keeping out of moving obstacles' way
--
-- GOTO_FAST (migration 8) with the dodge controller scenario (docs/CONTROLLER.md, "dodge"):
-- it follows the objects of the robot's scans from scan to scan and, when one that moves is
-- predicted to meet the robot within 2 s, recommends the evasive motion (yield, step out of
-- its way) at priority 90, above dwa and recovery; safety_stop keeps the last word.
INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) VALUES
    ('GOTO_DODGE', 'turn_then_move', '{dwa,dodge,safety_stop}',
     '{"target": "goal", "planner_drives": false, "recovery": true, "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05}',
     'go to the goal at the robot''s speed, keeping out of moving obstacles'' way: dwa along the planned path, dodge, recovery when stuck, safety_stop');

-- migration 16: learned models as data, and GOTO_LEARNED
--
-- A model trained on the records (`pnav learn train`, docs/LEARNING.md) is a file; the `model`
-- table is the people-written register of them: name, version, where the file is, and the
-- held-out metrics it was trained to. A strategy's params name the file and the version a
-- learned scenario must load (`learned_model`, `learned_model_version`), so switching a model
-- at run time is an UPDATE of the strategy row. GOTO_LEARNED drives with learned_drive along
-- the planner's path, with the planner's recovery and safety_stop; until a model file is at
-- `learned_drive.json` (relative to PNAV_MODEL_DIR) learned_drive stands down and the robot
-- does not drive.
CREATE TABLE model (
    name        text NOT NULL CHECK (length(name) BETWEEN 1 AND 64),
    version     text NOT NULL CHECK (length(version) BETWEEN 1 AND 64),
    path        text NOT NULL CHECK (length(path) BETWEEN 1 AND 1000),
    metrics     jsonb NOT NULL DEFAULT '{}'
        CHECK (jsonb_typeof(metrics) = 'object' AND octet_length(metrics::text) <= 16384),
    description text NOT NULL DEFAULT '' CHECK (char_length(description) <= 1000),
    created_at  timestamptz NOT NULL DEFAULT now(),
    PRIMARY KEY (name, version)
);

INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) VALUES
    ('GOTO_LEARNED', 'turn_then_move', '{learned_drive,safety_stop}',
     '{"target": "goal", "planner_drives": false, "recovery": true, "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05, "learned_model": "learned_drive.json"}',
     'go to the goal with learned_drive (a model trained on the records) along the planned path, recovery when stuck, safety_stop');

-- migration 17: a robot's footprint may be a polygon
--
-- Every robot was a disc of footprint_radius_m. A Jackal is a 508 x 430 mm box: the disc
-- inscribed in it lets its corners (0.33 m from the centre) into gaps the disc fits, and the
-- circumscribed one keeps it out of gaps it fits straight on. footprint_polygon gives the true
-- outline: vertices [x, y] in metres in the robot's frame (x forward, y left), in order,
-- counter-clockwise, the centre inside; a two-dimensional array, one row per vertex. NULL:
-- the disc of footprint_radius_m, as before (which stays, and keeps its meaning for readers
-- that take a radius). The bridge writes it from the robot's model. Three CHECKs, each naming
-- what is wrong (checked in the order of their names, so a malformed array is refused as
-- such, and a self-intersecting one before its centre is looked for):
-- robot_footprint_polygon_bounded (3 to 64 vertices, [x, y] each, finite, within 5 m of the
-- centre on each axis), robot_footprint_polygon_simple (no two edges cross or touch but
-- neighbours at their shared vertex, counter-clockwise), robot_footprint_polygon_surrounds_centre
-- (the centre inside, at least 1 mm from the outline). common/footprint.py
-- applies the same rules before the database does. Rows already present have NULL.
ALTER TABLE robot ADD COLUMN footprint_polygon double precision[];

CREATE FUNCTION footprint_polygon_bounded(p double precision[]) RETURNS boolean
LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT p IS NULL OR (
        array_ndims(p) = 2 AND array_lower(p, 1) = 1 AND array_lower(p, 2) = 1
        AND array_length(p, 2) = 2 AND array_length(p, 1) BETWEEN 3 AND 64
        AND NOT EXISTS (SELECT 1 FROM unnest(p) AS v
                         WHERE v IS NULL OR NOT is_finite(v) OR abs(v) > 5))
$$;

-- the centre (0, 0) strictly inside, at least 1 mm from every edge (crossing number, then
-- the distance to each edge); true for what footprint_polygon_bounded refuses
CREATE FUNCTION footprint_polygon_surrounds_centre(p double precision[]) RETURNS boolean
LANGUAGE plpgsql IMMUTABLE PARALLEL SAFE AS $$
DECLARE
    n integer;
    inside boolean := false;
    x1 double precision; y1 double precision; x2 double precision; y2 double precision;
    ex double precision; ey double precision; t double precision;
BEGIN
    IF p IS NULL OR NOT footprint_polygon_bounded(p) THEN
        RETURN true;
    END IF;
    n := array_length(p, 1);
    FOR i IN 1..n LOOP
        x1 := p[i][1]; y1 := p[i][2];
        x2 := p[i % n + 1][1]; y2 := p[i % n + 1][2];
        IF (y1 > 0) <> (y2 > 0) AND 0 < x1 + (0 - y1) * (x2 - x1) / (y2 - y1) THEN
            inside := NOT inside;
        END IF;
        ex := x2 - x1; ey := y2 - y1;
        t := CASE WHEN ex * ex + ey * ey = 0 THEN 0
                  ELSE greatest(0, least(1, (-x1 * ex - y1 * ey) / (ex * ex + ey * ey))) END;
        IF sqrt((x1 + t * ex) ^ 2 + (y1 + t * ey) ^ 2) < 0.001 THEN
            RETURN false;
        END IF;
    END LOOP;
    RETURN inside;
END;
$$;

-- no edge meets another but its neighbours at their shared vertex (no repeated vertex, no
-- neighbour folding back along its edge), and the signed area positive (counter-clockwise);
-- true for what footprint_polygon_bounded refuses
CREATE FUNCTION footprint_polygon_simple(p double precision[]) RETURNS boolean
LANGUAGE plpgsql IMMUTABLE PARALLEL SAFE AS $$
DECLARE
    n integer;
    area double precision := 0;
    xa double precision; ya double precision; xb double precision; yb double precision;
    xc double precision; yc double precision; xd double precision; yd double precision;
    o1 double precision; o2 double precision; o3 double precision; o4 double precision;
BEGIN
    IF p IS NULL OR NOT footprint_polygon_bounded(p) THEN
        RETURN true;
    END IF;
    n := array_length(p, 1);
    FOR i IN 1..n LOOP
        xa := p[i][1]; ya := p[i][2];
        xb := p[i % n + 1][1]; yb := p[i % n + 1][2];
        xc := p[(i + 1) % n + 1][1]; yc := p[(i + 1) % n + 1][2];
        IF xa = xb AND ya = yb THEN
            RETURN false;
        END IF;
        area := area + xa * yb - ya * xb;
        -- the next edge folding back along this one
        IF (xb - xa) * (yc - ya) - (yb - ya) * (xc - xa) = 0
           AND (xb - xa) * (xc - xb) + (yb - ya) * (yc - yb) < 0 THEN
            RETURN false;
        END IF;
        FOR j IN i + 2..n LOOP
            CONTINUE WHEN i = 1 AND j = n;  -- neighbours through vertex 1
            xc := p[j][1]; yc := p[j][2];
            xd := p[j % n + 1][1]; yd := p[j % n + 1][2];
            o1 := (xb - xa) * (yc - ya) - (yb - ya) * (xc - xa);
            o2 := (xb - xa) * (yd - ya) - (yb - ya) * (xd - xa);
            o3 := (xd - xc) * (ya - yc) - (yd - yc) * (xa - xc);
            o4 := (xd - xc) * (yb - yc) - (yd - yc) * (xb - xc);
            IF sign(o1) * sign(o2) < 0 AND sign(o3) * sign(o4) < 0 THEN
                RETURN false;
            END IF;
            -- touching: an end of one on the other
            IF (o1 = 0 AND xc BETWEEN least(xa, xb) AND greatest(xa, xb)
                       AND yc BETWEEN least(ya, yb) AND greatest(ya, yb))
               OR (o2 = 0 AND xd BETWEEN least(xa, xb) AND greatest(xa, xb)
                          AND yd BETWEEN least(ya, yb) AND greatest(ya, yb))
               OR (o3 = 0 AND xa BETWEEN least(xc, xd) AND greatest(xc, xd)
                          AND ya BETWEEN least(yc, yd) AND greatest(yc, yd))
               OR (o4 = 0 AND xb BETWEEN least(xc, xd) AND greatest(xc, xd)
                          AND yb BETWEEN least(yc, yd) AND greatest(yc, yd)) THEN
                RETURN false;
            END IF;
        END LOOP;
    END LOOP;
    RETURN area > 0;
END;
$$;

ALTER TABLE robot
    ADD CONSTRAINT robot_footprint_polygon_bounded
        CHECK (footprint_polygon_bounded(footprint_polygon)),
    ADD CONSTRAINT robot_footprint_polygon_surrounds_centre
        CHECK (footprint_polygon_surrounds_centre(footprint_polygon)),
    ADD CONSTRAINT robot_footprint_polygon_simple
        CHECK (footprint_polygon_simple(footprint_polygon));

-- migration 18: GOTO_FORESIGHT, and the params that name a model held to the register's rules
--
-- GOTO_FAST (migration 8) with foresight (pnav_learned/foresight.py, docs/LEARNING.md): a
-- controller scenario that predicts, from the last seconds of the robot's rows, that it will
-- make no progress in the next 3 s, and then backs up and turns early, at priority 60 (below
-- the planner's recovery, which still acts if the robot does get stuck). Its model is named
-- like learned_drive's: `foresight_model` (a name registered in the model table, or a file
-- relative to PNAV_MODEL_DIR: `foresight.json` here) and, optionally,
-- `foresight_model_version`. With no such model foresight stands down and GOTO_FORESIGHT
-- drives as GOTO_FAST.
--
-- strategy_model_params: the params naming a model are refused at the door unless they are
-- what the model table can hold (`*_model` a string of 1-1000 characters, as model.path;
-- `*_model_version` a string of 1-64, as model.version), and foresight_threshold, a
-- probability, within [0, 1]. NOT VALID: strategy rows are referenced (migration 3).
-- model_name_plain, model_version_plain: a model's name and version end up in every
-- learned recommendation's reason and in params people type: letters, digits, `_ . -` only.
INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) VALUES
    ('GOTO_FORESIGHT', 'turn_then_move', '{dwa,foresight,safety_stop}',
     '{"target": "goal", "planner_drives": false, "recovery": true, "battery_wh_per_m": 0.006, "battery_reserve_wh": 0.05, "foresight_model": "foresight.json"}',
     'go to the goal at the robot''s speed: dwa along the planned path, foresight recovering early when a model predicts no progress, recovery when stuck, safety_stop');

CREATE FUNCTION model_param_ok(p jsonb, k text, longest integer) RETURNS boolean
LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT NOT (p ? k) OR (jsonb_typeof(p -> k) = 'string'
                           AND char_length(p ->> k) BETWEEN 1 AND longest)
$$;

ALTER TABLE strategy ADD CONSTRAINT strategy_model_params CHECK (
    jsonb_typeof(params) <> 'object' OR (
        model_param_ok(params, 'learned_model', 1000)
        AND model_param_ok(params, 'learned_model_version', 64)
        AND model_param_ok(params, 'foresight_model', 1000)
        AND model_param_ok(params, 'foresight_model_version', 64)
        AND (NOT params ? 'foresight_threshold'
             OR (jsonb_typeof(params -> 'foresight_threshold') = 'number'
                 AND (params ->> 'foresight_threshold')::double precision BETWEEN 0 AND 1)))
) NOT VALID;

ALTER TABLE model
    ADD CONSTRAINT model_name_plain CHECK (name ~ '^[A-Za-z0-9_.-]+$') NOT VALID,
    ADD CONSTRAINT model_version_plain CHECK (version ~ '^[A-Za-z0-9_.-]+$') NOT VALID;

-- migration 19: GOTO_DODGE bends a box's roll-outs only where it could not turn in place
--
-- dwa's two-segment roll-outs for a footprint polygon ("straight on, then turn") commit to a
-- turn that dwa judges against the scan as if nothing moved, and dodge judges only the motion
-- being made: in the open, where the box could turn in place later, such a bend can lead it
-- into a mover's way. GOTO_DODGE, the strategy for worlds that move, keeps them only where
-- the box could not turn in place at the bend (`dwa_bends_in_open` 0; docs/CONTROLLER.md,
-- *dwa*). Other strategies keep the default, 1: bends wherever they score best.
UPDATE strategy SET params = params || '{"dwa_bends_in_open": 0}'
    WHERE code = 'GOTO_DODGE' AND jsonb_typeof(params) = 'object'
      AND NOT params ? 'dwa_bends_in_open';
