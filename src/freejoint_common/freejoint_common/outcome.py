"""
A plan's outcome in one line (freejoint_msgs/PlanOutcome).

What the planner's log, ``fj action send_goal`` and the analysis of a bag print.
"""


def outcome_line(outcome):
    """
    Return a plan's outcome as one line of text.

    Parameters
    ----------
    outcome : object
        Has PlanOutcome's fields: ``plan_id``, ``code_name``, ``message``, ``elapsed``,
        ``lateness``, ``pauses``, ``time_paused`` [s], ``max_path_error`` [m] (a message,
        a decoded bag record or ``freejoint_planner.plan_goal.Outcome``).

    Returns
    -------
    str
        ``plan N CODE_NAME: message (elapsed .. s, late .. s, n pause(s) .. s, max path
        error .. mm)``; a refused request (plan 0) without the figures.

    """
    line = 'plan %d %s' % (outcome.plan_id, outcome.code_name)
    if outcome.message:
        line += ': ' + outcome.message
    if outcome.plan_id:
        line += (' (elapsed %.3f s, late %.3f s, %d pause(s) %.3f s, max path error %.2f mm)'
                 % (outcome.elapsed, outcome.lateness, outcome.pauses, outcome.time_paused,
                    outcome.max_path_error * 1e3))
    return line
