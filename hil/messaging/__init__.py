"""The controller's face to other processes: ROS 2 message layouts as CDR
(:mod:`~hil.messaging.cdr`), hil's Zenoh keys (:mod:`~hil.messaging.keys`), the trajectory
action (:mod:`~hil.messaging.action`), the other publications and subscriptions
(:mod:`~hil.messaging.zenoh_api`), diagnostics and control samples, and the ROS 2 face on
rmw_zenoh (:mod:`~hil.messaging.ros`)."""
