"""The neural render behind the viewer's Neural render panel: the progressive render
worker in a thread (:mod:`.worker`) or in processes of their own (:mod:`.render_process`),
and the wake that has the idling window draw a level as soon as it arrives (:mod:`.wake`)."""
